"""The experiment's DDS transport (docs/experiment.md, "Transports"): :mod:`.transport` launches a method's graph and
runs episodes through it; :mod:`.collector` and :mod:`.fleet_collector` record them over DDS."""
