"""Colours every picture of the stack shares (the live scene's markers, the demo's PNG and GIF): one place, so that
ego i has the same colour in Foxglove and in the files ``avp demo`` writes. Plain tuples, no imports."""

#: ego i's colour (RGB, 0..1) among several egos
EGO_RGB = ((0.9, 0.1, 0.1), (1.0, 0.55, 0.0), (0.6, 0.2, 0.9), (0.0, 0.8, 0.7), (0.95, 0.3, 0.7), (0.55, 0.8, 0.1),
           (0.6, 0.4, 0.2), (0.1, 0.6, 1.0))
