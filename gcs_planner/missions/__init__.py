"""Plans as mission items, their validation, and the mission and parameter files of the field's tools."""
