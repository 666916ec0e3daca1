"""Every error of ``mjx-arm`` is one short line (:mod:`mjx_arm.cli`): argparse errors, named
errors, and long reports, which go to an error-report file the line names."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from mjx_arm.cli import MAX_LINE_CHARS, build_parser, error_line, main, report_folders
from mjx_arm.inputs import InputError

ARM_URDF = Path(__file__).resolve().parents[1] / "assets" / "ur5e.urdf"


def chain_urdf(path: Path, joints: int) -> Path:
    """A serial chain of ``joints`` revolute joints (``joints + 1`` links) written to ``path``."""
    inertial = (
        '<inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" '
        'ixz="0" iyz="0"/></inertial>'
    )
    box = '<collision><geometry><box size="0.05 0.05 0.05"/></geometry></collision>'
    lines = ['<robot name="chain">']
    lines += [f'<link name="l{i}">{inertial}{box}</link>' for i in range(joints + 1)]
    lines += [
        f'<joint name="j{i}" type="revolute"><parent link="l{i}"/><child link="l{i + 1}"/>'
        '<origin xyz="0 0 0.01"/><axis xyz="0 0 1"/>'
        '<limit lower="-1" upper="1" effort="10" velocity="1"/><dynamics damping="0.1"/></joint>'
        for i in range(joints)
    ]
    path.write_text("\n".join([*lines, "</robot>"]))
    return path


def _subcommands() -> list[str]:
    (sub,) = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    return sorted(sub.choices)


def _run(argv: list[str]) -> int:
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else 1


def _one_error_line(argv: list[str], capsys) -> str:
    """Run ``mjx-arm argv`` in process; check exit code 2 and exactly one short ``error:`` line
    on stderr, and return it."""
    code = _run(argv)
    err = capsys.readouterr().err
    lines = err.splitlines()
    assert code == 2, (argv, code, err)
    assert len(lines) == 1 and lines[0].startswith("error: "), (argv, err)
    assert len(lines[0]) <= MAX_LINE_CHARS, (argv, len(lines[0]), lines[0])
    return lines[0]


@pytest.fixture(autouse=True)
def _state_home(tmp_path: Path, monkeypatch) -> Path:
    """Error reports go under the test's folder."""
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    return tmp_path / "state"


@pytest.mark.parametrize("command", _subcommands())
def test_an_unknown_option_of_every_subcommand_is_one_line(command: str, capsys):
    line = _one_error_line([command, "--no-such-option"], capsys)
    assert "--no-such-option" in line or "arguments are required" in line  # reported first
    assert line.endswith(f"(see: mjx-arm {command} --help)")


BAD_ARGVS = [  # ([] and ["bench"] print their help: test_cli.py)
    ["trian"],
    ["convert"],
    ["convert", str(ARM_URDF)],
    ["validate", "x.urdf", "--engine", "bullet"],
    ["convert", str(ARM_URDF), "-o", "x.xml", "--default-effort", "-1"],
    ["convert", str(ARM_URDF), "-o", "x.xml", "--scene", "moon"],
    ["validate", "/no/such/arm.urdf"],
    ["validate", str(ARM_URDF), "--package", "nofolder"],
    ["validate", str(ARM_URDF), "--package", "p=/no/such/folder/" + "x" * 400],
    ["train", "--set", "num_env=64"],
    ["train", "--set", "n" * 500 + "=1"],
    ["eval", "/no/such/policy.npz"],
    ["bench", "nosuch"],
    ["bench", "transfer", "policy.npz", "--no-such-option"],
]


@pytest.mark.parametrize("argv", BAD_ARGVS, ids=lambda a: " ".join(a)[:40] or "(none)")
def test_bad_arguments_give_one_short_error_line(argv: list[str], capsys):
    _one_error_line(argv, capsys)


def test_a_mistyped_setting_is_named_with_its_likely_meaning(capsys):
    line = _one_error_line(["train", "--set", "num_env=64"], capsys)
    assert "'num_env'" in line and "did you mean 'num_envs'?" in line
    line = _one_error_line(["train", "--set", "physics.impll=jax"], capsys)
    assert "'impll' (did you mean 'impl'?) in 'physics'" in line


def test_a_missing_urdf_is_one_error_line(capsys):
    line = _one_error_line(["validate", "/no/such/arm.urdf"], capsys)
    assert line.count("/no/such/arm.urdf") == 1 and "does not exist" in line
    assert capsys.readouterr().out == ""


def test_a_failed_conversion_is_summarised_and_reported_in_full(tmp_path, capsys, _state_home):
    urdf = chain_urdf(tmp_path / "deep.urdf", 400)
    line = _one_error_line(["convert", str(urdf), "-o", str(tmp_path / "deep.xml")], capsys)
    assert "1 error (link 'l400': is 401 links down" in line
    urdf_error = str(urdf) + ": 1 error"
    assert line.startswith(f"error: {urdf_error}")
    assert "Validating" not in line  # the report went to stdout


def test_a_long_message_is_cut_keeping_cause_and_fix_and_written_in_full(tmp_path, capsys):
    cause = "the widget " + "w" * 600 + " is broken"
    err = InputError(f"{cause}; some detail; replace the widget")
    args = argparse.Namespace(out=str(tmp_path))
    line = error_line(err, args, ["demo", "--out", str(tmp_path)])
    assert len(line) <= MAX_LINE_CHARS
    assert (
        line.startswith("error: the widget www") and "; replace the widget (full report: " in line
    )
    report = Path(line.rsplit("(full report: ", 1)[1].rstrip(")"))
    assert report.parent == tmp_path  # the command's own output folder
    text = report.read_text()
    assert cause in text and "mjx-arm demo --out" in text and "InputError" in text


def test_a_short_message_is_printed_as_it_is(tmp_path, _state_home):
    line = error_line(InputError("a; b"), argparse.Namespace(), [])
    assert line == "error: a; b" and not _state_home.exists()


def test_reports_go_to_the_state_folder_else_the_temp_folder(tmp_path, _state_home):
    folders = report_folders(argparse.Namespace(out=str(tmp_path / "missing"), run=None))
    assert folders[0] == _state_home / "mjx_arm" / "errors"
    assert folders[1].name == "mjx_arm-errors"
    (_state_home).write_text("a file, not a folder")  # the state folder cannot be written
    line = error_line(InputError("x" * 400 + "; fix it"), argparse.Namespace(), [])
    report = Path(line.rsplit("(full report: ", 1)[1].rstrip(")"))
    assert report.parent.name == "mjx_arm-errors" and "x" * 400 in report.read_text()
    report.unlink()


def test_a_failed_validation_at_a_long_path_is_one_short_line(tmp_path, capsys):
    folder = tmp_path / ("d" * 200)
    folder.mkdir()
    urdf = chain_urdf(folder / "deep.urdf", 300)
    line = _one_error_line(["validate", str(urdf), "--engine", "mujoco"], capsys)
    assert line.startswith("error: .../deep.urdf: 1 error (link 'l300': is 301 links down")


def test_a_long_output_folder_is_passed_over_for_the_report(tmp_path, _state_home):
    folder = tmp_path / ("o" * 200)
    folder.mkdir()
    line = error_line(InputError("y" * 400 + "; fix it"), argparse.Namespace(out=str(folder)), [])
    assert len(line) <= MAX_LINE_CHARS and line.endswith(".txt)")
    report = Path(line.rsplit("(full report: ", 1)[1].rstrip(")"))
    assert report.parent == _state_home / "mjx_arm" / "errors"


def test_many_errors_with_long_names_are_one_short_line(tmp_path, capsys):
    """60 joints without <limit>, every name 250 characters long: the count and the first two,
    cut to fit."""
    name = "n" * 250
    inertial = '<inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1"/></inertial>'
    lines = ['<robot name="r">', f'<link name="{name}0">{inertial}</link>']
    for i in range(1, 61):
        lines.append(f'<link name="{name}{i}">{inertial}</link>')
        lines.append(
            f'<joint name="{name}j{i}" type="revolute"><parent link="{name}0"/>'
            f'<child link="{name}{i}"/><axis xyz="0 0 1"/></joint>'
        )
    urdf = tmp_path / "many.urdf"
    urdf.write_text("\n".join([*lines, "</robot>"]))
    line = _one_error_line(["validate", str(urdf), "--engine", "mujoco"], capsys)
    assert ": 60 errors (joint 'nnn" in line and "; and 58 more)" in line
