"""A misspelt scenario key is an error naming it and the nearest known one, never silently
ignored: `[obstacle]` for `[obstacles]` used to drop every tower and plan straight through them."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from gcs_planner.cli import main
from gcs_planner.core.errors import UserError
from gcs_planner.planning import load_scenario, parse_scenario

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


MISSIONS = Path(__file__).resolve().parents[1] / "missions"


@pytest.mark.parametrize(
    ("mission", "mutate", "message"),
    [
        ("coalition_paper", lambda d: d["coalition"].update(target=[]), "[coalition]: unknown key 'target'"),
        (
            "coalition_paper",
            lambda d: d["coalition"]["targets"][0].update(recon_uvs="U1"),
            "coalition.targets[0]: unknown key 'recon_uvs'; did you mean 'recon_uav'?",
        ),
        (
            "coalition_paper",
            lambda d: d["coalition"]["threats"][0].update(radius=9.0),
            "coalition.threats[0]: unknown key 'radius'; did you mean 'radius_m'?",
        ),
        ("acmpso_paper", lambda d: d["terrain"].update(peak=[]), "[terrain]: unknown key 'peak'"),
        (
            "acmpso_paper",
            lambda d: d["terrain"]["peaks"][1].update(hm=1.0),
            "terrain.peaks[1]: unknown key 'hm'; did you mean 'h_m'?",
        ),
        (
            "deconflict_10uav_manned",
            lambda d: d["manned"][0].update(velocity=[1, 0, 0]),
            "manned[0]: unknown key 'velocity'; did you mean 'velocity_mps'?",
        ),
        (
            "deconflict_10uav_manned",
            lambda d: d["manned"][0]["modes"][0].update(sigma=[1, 1, 1]),
            "manned[0].modes[0]: unknown key 'sigma'; did you mean 'sigma_mps'?",
        ),
        ("acmpso_paper", lambda d: d.update(acmpso={}), "the [acmpso] table's keys now belong in [planner]"),
    ],
)
def test_misspelt_keys_in_planner_tables_are_named_when_loaded(tmp_path, mission, mutate, message):
    data = tomllib.loads((MISSIONS / f"{mission}.toml").read_text())
    mutate(data)
    with pytest.raises(UserError) as err:
        parse_scenario(data)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_a_misspelt_planner_key_fails_the_cli_before_planning(tmp_path, capsys):
    text = (MISSIONS / "swarm_small.toml").read_text().replace("[planner]", "[planner]\nparticle = 3", 1)
    path = tmp_path / "bad.toml"
    path.write_text(text)
    assert main(["plan", str(path), "-o", str(tmp_path / "p.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("planner: unknown key 'particle'; did you mean 'particles'?") and "\n" not in err
    assert not (tmp_path / "p.json").exists()
    for mission in sorted(MISSIONS.glob("*.toml")):  # and every bundled scenario loads
        load_scenario(mission)
