"""The model: scenarios, sites and terrain in, plans out (Scenario, Plan, their checks)."""
