"""gcs-planner: plan UAV swarm missions, upload them over MAVLink, fly, log and replay them."""

__version__ = "0.1.0"
