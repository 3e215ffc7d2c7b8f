"""canest init over every DBC opendbc ships (files and generated) and from opendbc's car parameters.

Needs the optional package opendbc (`pip install 'canest[opendbc]'`, in the `test` extra); without it the
module is skipped, and only then.
"""
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest
import yaml

opendbc = pytest.importorskip("opendbc", reason="opendbc is not installed: pip install 'canest[opendbc]' "
                                                "(the test extra installs it)")

from canest.apps.init import starting_config, write_new  # noqa: E402
from canest.config import load_config  # noqa: E402
from canest.config.opendbc_cars import dbc_names  # noqa: E402
from canest.errors import CanestError, DbcError  # noqa: E402
from canest.estimation.catalog import BASE_INPUTS  # noqa: E402
from tests.conftest import ROOT  # noqa: E402

CANEST = [sys.executable, "-m", "canest"]


def canest(*args):
    return subprocess.run([*CANEST, *map(str, args)], capture_output=True, text=True, timeout=300, cwd=ROOT)


def opendbc_file(folder, name):
    """opendbc's DBC ``name`` as a file, as a user who has the DBC would have it (generated ones are text)."""
    generated = opendbc.get_generated_dbcs()
    path = folder / f"{name}.dbc"
    if name in generated:
        path.write_text(generated[name])
    else:
        path.write_bytes(Path(opendbc.DBC_PATH, f"{name}.dbc").read_bytes())
    return path


def test_every_opendbc_dbc_gives_a_config_check_accepts_or_one_error_naming_what_it_lacks(tmp_path):
    outcomes = Counter()
    names = dbc_names()
    assert len(names) >= 90  # files and generated ones
    for name in names:
        dbc = opendbc_file(tmp_path, name)
        out = tmp_path / f"{name}.yaml"
        try:
            text, found = starting_config(str(dbc), out=out)
        except CanestError as exc:
            assert isinstance(exc, DbcError) and exc.exit_status == 2, (name, exc)
            message = str(exc)
            assert message.startswith(f"{dbc}: ") and "\n" not in message, (name, message)
            assert "no signal found for " in message, (name, message)  # every opendbc DBC loads (repaired)
            # the inputs named are exactly those not found, each an input every model needs
            named = message.split("no signal found for ")[1].split(" (")[0].split(", ")
            assert named and set(named) <= set(BASE_INPUTS), (name, message)
            outcomes["lacks inputs"] += 1
            assert not out.exists()
            continue
        write_new(out, text)
        config = load_config(out)  # what `canest check` loads
        assert set(config.signals) == set(found) >= set(BASE_INPUTS), name
        outcomes["config written"] += 1
    print(f"\ncanest init over {len(names)} opendbc DBCs: {dict(outcomes)}")
    assert outcomes["config written"] >= 5
    assert sum(outcomes.values()) == len(names)


@pytest.mark.parametrize("name", ["ford_lincoln_base_pt", "toyota_prius_2010_pt", "hyundai_2015_ccan", "vw_mlb"])
def test_the_cli_writes_a_config_check_accepts_for_cars_with_every_input(tmp_path, name):
    dbc = opendbc_file(tmp_path, name)
    out = tmp_path / f"{name}.yaml"
    result = canest("init", "--dbc", dbc, "--out", out)
    assert result.returncode == 0, result.stderr
    check = canest("check", "--config", out)
    assert check.returncode == 0, check.stderr
    assert check.stdout.rstrip().endswith("OK")


def test_the_cli_names_what_a_radar_dbc_lacks(tmp_path):
    dbc = opendbc_file(tmp_path, "ESR")
    result = canest("init", "--dbc", dbc, "--out", tmp_path / "esr.yaml")
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and "no signal found for wheel_speed_fl" in result.stderr
    assert not (tmp_path / "esr.yaml").exists()


def test_car_parameters_come_from_opendbc_each_with_its_source(tmp_path):
    from opendbc.car.car_helpers import interfaces

    params = interfaces["FORD_FOCUS_MK4"].get_non_essential_params("FORD_FOCUS_MK4")
    dbc = opendbc_file(tmp_path, "ford_lincoln_base_pt")
    out = tmp_path / "focus.yaml"
    result = canest("init", "--dbc", dbc, "--car", "FORD_FOCUS_MK4", "--out", out)
    assert result.returncode == 0, result.stderr
    vehicle = load_config(out).vehicle
    assert vehicle.mass == pytest.approx(params.mass, abs=0.1)
    assert vehicle.wheelbase == pytest.approx(params.wheelbase, abs=1e-3)
    assert vehicle.cg_to_front == pytest.approx(params.centerToFront, abs=1e-3)
    assert vehicle.steering_ratio == pytest.approx(params.steerRatio, abs=1e-3)
    assert vehicle.cornering_stiffness_front == pytest.approx(params.tireStiffnessFront, abs=1.0)
    assert vehicle.cornering_stiffness_rear == pytest.approx(params.tireStiffnessRear, abs=1.0)
    assert vehicle.yaw_inertia == pytest.approx(params.rotationalInertia, abs=0.1)
    lines = {line.split(":")[0].strip(): line for line in out.read_text().splitlines() if line.startswith("  ")}
    assert "opendbc FORD_FOCUS_MK4: CarParams.mass" in lines["mass"]
    assert "canest's default" in lines["track_front"] and "canest's default" in lines["wheel_radius"]
    assert canest("check", "--config", out).returncode == 0


def test_a_car_opendbc_does_not_describe_and_an_unknown_dbc_name_are_one_line_with_the_closest():
    result = canest("init", "--car", "FORD_FOCUS_MK5")
    assert result.returncode == 2 and "FORD_FOCUS_MK4" in result.stderr and result.stderr.count("\n") == 1
    result = canest("init", "--dbc", "opendbc:ford_lincoln_base")
    assert result.returncode == 2 and "ford_lincoln_base_pt" in result.stderr and result.stderr.count("\n") == 1


def test_init_from_a_car_alone_takes_its_own_dbc(tmp_path):
    result = canest("init", "--car", "FORD_FOCUS_MK4")
    assert result.returncode == 0, result.stderr
    document = yaml.safe_load(result.stdout)
    assert document["input"]["dbc"] == "opendbc:ford_lincoln_base_pt"
    assert document["vehicle"]["name"] == "ford-focus-mk4"
