"""The one safety checker of plans (separation, clearance, site) and of flown tracks, and the fence."""
