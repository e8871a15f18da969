"""MAVLink services: links, transports, the mission, command and parameter protocols, fleets, autopilots."""
