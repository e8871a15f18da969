"""A misspelt scenario key is an error naming it and the nearest known one, never silently
ignored: `[obstacle]` for `[obstacles]` used to drop every tower and plan straight through them."""

from __future__ import annotations

import pytest

from gcs_planner.errors import UserError
from gcs_planner.scenario import parse_scenario

BASE = {
    "origin": {"lat_deg": 47.4, "lon_deg": 8.5, "alt_m": 400.0},
    "planner": {"name": "straight"},
    "vehicles": [{"id": "a", "sysid": 1, "start": [0.0, 0.0, 0.0], "goal": [100.0, 0.0, 20.0]}],
    "obstacles": {"cylinders": [{"x": 50.0, "y": 0.0, "radius_m": 5.0}]},
}


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (
            lambda d: d.update(obstacle=d.pop("obstacles")),
            "unknown key 'obstacle'; did you mean 'obstacles'?",
        ),
        (lambda d: d["vehicles"][0].update(turn_raduis_m=5.0), "did you mean 'turn_radius_m'?"),
        (lambda d: d["obstacles"]["cylinders"][0].update(raduis_m=9.0), "did you mean 'radius_m'?"),
        (lambda d: d["obstacles"].update(cylinder=[]), "[obstacles]: unknown key 'cylinder'"),
        (lambda d: d["origin"].update(lat=1.0), "[origin]: unknown key 'lat'"),
    ],
)
def test_misspelt_keys_are_named(mutate, message):
    data = {k: (v.copy() if isinstance(v, dict) else v) for k, v in BASE.items()}
    data["vehicles"] = [dict(BASE["vehicles"][0])]
    data["obstacles"] = {"cylinders": [dict(BASE["obstacles"]["cylinders"][0])]}
    mutate(data)
    with pytest.raises(UserError) as err:
        parse_scenario(data)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_the_correct_spelling_parses():
    assert len(parse_scenario(BASE).cylinders) == 1
