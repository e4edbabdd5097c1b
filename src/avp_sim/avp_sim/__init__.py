"""Parking-lot simulator: occlusion-aware ray-casting observations, reactive agents doing ParkSim maneuvers, seeded scenarios, episode metrics (paper §III, §VI-A)."""
