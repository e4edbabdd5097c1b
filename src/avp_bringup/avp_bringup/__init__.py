"""Launch files, parameter files, the avp command line (launch, demo) and rendering."""
