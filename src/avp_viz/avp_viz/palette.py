"""Colours every picture of the stack shares (the live scene's markers, the demo's PNG and GIF), and which spots get
their belief's colour: one place, so that ego i has the same colour, and a spot the same shade, in Foxglove and in the
files ``avp demo`` writes. Plain tuples and loops, no imports."""

#: ego i's colour (RGB, 0..1) among several egos
EGO_RGB = ((0.9, 0.1, 0.1), (1.0, 0.55, 0.0), (0.6, 0.2, 0.9), (0.0, 0.8, 0.7), (0.95, 0.3, 0.7), (0.55, 0.8, 0.1),
           (0.6, 0.4, 0.2), (0.1, 0.6, 1.0))


def mark_seen(seen, lot, obs) -> None:
    """Set ``seen`` (one flag per spot of ``lot``) for every spot the observation ``obs`` reports, vacant or occupied:
    the spots the ego has observed, drawn in their belief's colour (the others grey). An id the lot lacks is skipped."""
    for sid in (*obs.vacant_spot_ids, *obs.occupied_spot_ids):
        if lot.has_spot(int(sid)):
            seen[lot.spot_index(int(sid))] = True
