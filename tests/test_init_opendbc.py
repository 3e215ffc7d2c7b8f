"""canest init over every DBC opendbc ships (files and generated) and from opendbc's car parameters.

Needs the optional package opendbc (`pip install 'canest[opendbc]'`, in the `test` extra); without it the
module is skipped, and only then.
"""
import math
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest
import yaml

opendbc = pytest.importorskip("opendbc", reason="opendbc is not installed: pip install 'canest[opendbc]' "
                                                "(the test extra installs it)")

from canest.apps.init import starting_config, write_new  # noqa: E402
from canest.cli import main  # noqa: E402
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


def full_check(config, capsys) -> str:
    """``canest check --config config`` run in this process (94 interpreters would take minutes): its output."""
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_status:
        main(["check", "--config", str(config)])
    out = capsys.readouterr()
    assert exit_status.value.code == 0, out.err
    assert out.out.rstrip().endswith("OK")
    return out.out


def test_every_opendbc_dbc_gives_a_config_check_accepts_or_one_error_naming_what_it_lacks(tmp_path, capsys):
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
        config = load_config(out)
        assert set(config.signals) == set(found) >= set(BASE_INPUTS), name
        checked = full_check(out, capsys)
        assert "raw counts" not in checked, (name, checked)  # init overrode every raw-style range it took
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


def test_a_file_of_opendbc_s_own_is_written_by_its_name_and_no_scratch_path_is_shown(tmp_path):
    """The generated DBC in canest's cache (or opendbc's package folder) moves with a cache clean or an install:
    the config names it opendbc:NAME. Its tolerated problems name the DBC as given, not init's scratch folder."""
    from canest.codec.opendbc_dbcs import opendbc_path

    cached = opendbc_path("toyota_nodsu_pt_generated", "test")
    result = canest("init", cached, "--out", tmp_path / "rav4.yaml")
    assert result.returncode == 0, result.stderr
    text = (tmp_path / "rav4.yaml").read_text()
    assert yaml.safe_load(text)["input"]["dbc"] == "opendbc:toyota_nodsu_pt_generated"
    assert str(cached.parent) not in text and "canest-init-" not in text + result.stderr
    assert "the config: input.dbc opendbc:toyota_nodsu_pt_generated: The signals PCS_TEMP and SET_ME_X10 are " \
           "overlapping" in result.stderr
    signals = yaml.safe_load(text)["input"]["signals"]
    assert signals["yaw_rate"] == {"signal": "KINEMATICS.YAW_RATE", "range": "none"}
    static = Path(opendbc.DBC_PATH) / "ford_lincoln_base_pt.dbc"
    assert yaml.safe_load(canest("init", static).stdout)["input"]["dbc"] == "opendbc:ford_lincoln_base_pt"


def test_the_config_init_writes_for_a_toyota_drives_it_without_an_edit(tmp_path):
    """opendbc's RAV4 as it ships: init overrides the raw-count KINEMATICS ranges (range: none) and gives no cycle
    time (the DBC has none: replay measures them); with the DBC's ranges the negative values are rejected."""
    from tests.test_toyota_drive import drive

    out = tmp_path / "rav4.yaml"
    write_new(out, starting_config("opendbc:toyota_nodsu_pt_generated", car="TOYOTA_RAV4_TSS2", out=out)[0])
    summary, errors, normal = drive(load_config(out), tmp_path, "init")
    assert normal >= 0.99 and summary["decoded"] == summary["frames"]
    assert errors["vx"] < 0.1 and errors["yaw_rate"] < math.radians(0.5)
    document = yaml.safe_load(out.read_text())
    document["input"]["signals"]["yaw_rate"] = document["input"]["signals"]["yaw_rate"]["signal"]
    out.write_text(yaml.safe_dump(document))
    summary, _, normal = drive(load_config(out), tmp_path, "dbc_range")
    assert summary["rejected_out_of_range"] > 100 and normal < 0.9
