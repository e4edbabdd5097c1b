"""Parking-lot simulator (paper §III, §VI-A).

Occlusion-aware ray-casting observations, reactive agents doing ParkSim maneuvers, seeded scenarios,
episode metrics.
"""
