"""MAVLink adaptor: plans to mission items, the mission protocol client, links, plan files."""
