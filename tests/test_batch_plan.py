"""Fleet replay planning on real files, without a cluster: which logs, where their results go, which truth."""
import os
import shutil
from pathlib import Path

import pytest

from canest.apps.batch_plan import CODE, file_fingerprint, find_logs, fingerprint, input_root, plan, truth_for
from canest.errors import UsageError


def touch(path: Path, text: str = "x") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def test_logs_of_one_stem_get_one_result_folder_each(tmp_path):
    a_log, a_blf = touch(tmp_path / "logs" / "day1" / "a.log"), touch(tmp_path / "logs" / "day1" / "a.blf")
    touch(tmp_path / "logs" / "day1" / "a.truth.csv")
    logs = find_logs([str(tmp_path / "logs" / "**" / "*")], tmp_path / "out")
    assert logs == [a_blf, a_log]  # the truth file is no log
    tasks = plan(logs, ["ckf", "ekf"], input_root([str(tmp_path / "logs" / "**" / "*")]), tmp_path / "out")
    assert [t.out.relative_to(tmp_path / "out").as_posix() for t in tasks] == [
        "day1/a.blf/ckf", "day1/a.blf/ekf", "day1/a.log/ckf", "day1/a.log/ekf"]


@pytest.mark.parametrize("patterns, root", [
    (["logs/**/*.log"], "logs"),
    (["logs/day1/*.log", "logs/day2/*.blf"], "logs"),
    (["logs/day1/a.log"], "logs/day1"),
    (["*.log"], "."),
    (["logs/day[12]/*.log"], "logs"),
])
def test_input_root_is_where_the_patterns_start(tmp_path, monkeypatch, patterns, root):
    monkeypatch.chdir(tmp_path)
    assert input_root(patterns) == Path(os.path.abspath(tmp_path / root))


def test_results_inside_the_input_are_not_read_as_logs(tmp_path):
    log = touch(tmp_path / "data" / "drive.csv")
    for name in ("estimates.csv", "summary.json", "estimates.csv.0123abcd.tmp"):
        touch(tmp_path / "data" / "results" / "drive.csv" / "ckf" / name)
    touch(tmp_path / "data" / "results" / "fleet_summary.csv")
    assert find_logs([str(tmp_path / "data" / "**" / "*")], tmp_path / "data" / "results") == [log]


def test_results_in_the_logs_own_folder_are_refused(tmp_path):
    log = touch(tmp_path / "drive.log")
    with pytest.raises(UsageError, match=f"--out {tmp_path}: the results of {log} would go into {log}, which is a file"):
        plan(find_logs([str(tmp_path / "*.log")], tmp_path), ["ckf"], input_root([str(tmp_path / "*.log")]), tmp_path)


def test_no_log_is_a_usage_error(tmp_path):
    with pytest.raises(UsageError, match="no log matches"):
        find_logs([str(tmp_path / "*.log")], tmp_path / "out")


def test_truth_named_after_the_whole_log_name_comes_before_the_stem(tmp_path):
    log, blf = touch(tmp_path / "b.log"), touch(tmp_path / "b.blf")
    assert truth_for(log) is None
    stem = touch(tmp_path / "b_truth.csv")
    assert truth_for(log) == stem and truth_for(blf) == stem
    stem = touch(tmp_path / "b.truth.csv")
    assert truth_for(log) == stem and truth_for(blf) == stem  # .truth.csv before _truth.csv
    whole = touch(tmp_path / "b.log_truth.csv")
    assert truth_for(log) == whole and truth_for(blf) == stem
    whole = touch(tmp_path / "b.log.truth.csv")
    assert truth_for(log) == whole and truth_for(blf) == stem


@pytest.mark.parametrize("offset", [0, 65_535, 200_000, -1])  # first and last byte of the head, in the tail, last
def test_fingerprint_sees_an_edit_of_head_or_tail_with_size_and_mtime_kept(tmp_path, offset):
    log = tmp_path / "drive.log"
    log.write_bytes(bytes(range(256)) * 1024)  # 256 KiB
    before = file_fingerprint(log)
    stat = os.stat(log)
    data = bytearray(log.read_bytes())
    data[offset] ^= 0xFF
    log.write_bytes(bytes(data))
    os.utime(log, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    after = file_fingerprint(log)
    assert (after["bytes"], after["mtime_ns"]) == (before["bytes"], before["mtime_ns"])
    assert after["sha256_head_tail"] != before["sha256_head_tail"]


def test_fingerprint_sees_a_touch(tmp_path):
    log = touch(tmp_path / "drive.log")
    before = file_fingerprint(log)
    stat = os.stat(log)
    os.utime(log, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000_000))
    assert file_fingerprint(log)["mtime_ns"] != before["mtime_ns"]


def test_the_config_fingerprint_covers_canests_code(config, tmp_path):
    """A result computed by another canest build is not current: editing any module of the package changes the
    fingerprint; a file that is not code (a cache) does not."""
    code = tmp_path / "canest"
    shutil.copytree(CODE, code, ignore=shutil.ignore_patterns("__pycache__"))
    before = fingerprint(config, code)
    assert fingerprint(config) == fingerprint(config, CODE) and before == fingerprint(config, code)
    (code / "notes.pyc").write_bytes(b"not code")
    assert fingerprint(config, code) == before
    filters = code / "filters" / "sigma.py"
    filters.write_text(filters.read_text() + "\n# another build\n")
    assert fingerprint(config, code) != before
