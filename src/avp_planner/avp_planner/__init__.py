"""Ego planner (paper §V-D); for now a scripted driver node."""
