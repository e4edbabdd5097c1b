"""The viewers: the scene node (/tf, 3-D markers), the Foxglove bridge, the top-down renderer, the episode GIF."""
