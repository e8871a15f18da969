"""Sites: a scenario's world in geodetic terms, read from the operator's map files.

``[site]`` in a scenario (docs/sites.md) names GeoJSON / KML / KMZ features (the operating area,
no-fly zones, obstacles with heights) and a DEM (SRTM .hgt or GeoTIFF); ``[[vehicles]]`` may give
``start_lla`` / ``goal_lla``. Modules: features (the checked feature model), geojson and kml (the
readers), dem (the elevation grids), world (the site in local metres, Scenario.site) and checks
(what the plan checker proves on a site). The package builds on gcs_planner.core.geo, .terrain and
.validation only, so the scenario reader, the geometry checks and the planners can all use it.
"""
