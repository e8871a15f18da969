"""The MAVLink wire core: message types, enums, framing, codec, signing, units.

What the GCS and the mock autopilot (sitl_mock) share; it imports nothing else of gcs_planner."""
