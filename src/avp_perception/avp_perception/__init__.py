"""Belief map, BEV reconstruction, intent CNN and trajectory prediction (paper §V-A..C)."""
