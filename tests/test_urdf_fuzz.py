"""Hostile and broken URDFs: safe XML reading, files outside the URDF's folder, seeded mutations.

The 500-mutation run (:func:`test_seeded_mutations_get_named_errors_or_pass`) runs every mutant
through ``validate``, ``to_mjcf``, ``mjx-arm validate`` and ``mjx-arm convert`` in a worker
process (:mod:`urdf_fuzz.harness`); about 80 s on a 2-core CPU.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from mjx_arm.cli import main
from mjx_arm.paths import default_arm_urdf
from mjx_arm.urdf import ConversionError, to_mjcf
from mjx_arm.urdf.meshes import AssetPathError, find_package_dir, resolve_asset
from mjx_arm.urdf.safe_xml import (
    MAX_ATTRIBUTE_CHARS,
    MAX_BYTES,
    MAX_DEPTH,
    XmlError,
    parse_xml,
    read_xml,
)
from mjx_arm.urdf.validate import validate
from urdf_fuzz.harness import HANG_SECONDS, OPS, STATUSES, _OpenAudit, run_fuzz, tally
from urdf_fuzz.mutate import KINDS, mutant, mutants

ARM = default_arm_urdf().read_text()
FUZZ_MUTATIONS = 500
FUZZ_SEED = 0

# --------------------------------------------------------------------------- hostile XML

BILLION_LAUGHS = (
    '<!DOCTYPE robot [<!ENTITY a "lol">'
    + "".join(f'<!ENTITY {chr(98 + i)} "{f"&{chr(97 + i)};" * 10}">' for i in range(9))
    + ']><robot name="&j;"/>'
)
DOCTYPES = {
    "billion_laughs": (BILLION_LAUGHS, "declares entity 'a' (text)"),
    "external_entity": (
        '<!DOCTYPE robot [<!ENTITY x SYSTEM "file:///etc/passwd">]><robot name="&x;"/>',
        "declares entity 'x' (external file 'file:///etc/passwd')",
    ),
    "parameter_entity": (
        '<!DOCTYPE robot [<!ENTITY % p SYSTEM "file:///etc/passwd"> %p;]><robot name="a"/>',
        "declares parameter entity 'p'",
    ),
    "external_dtd": (
        '<!DOCTYPE robot SYSTEM "file:///etc/passwd"><robot name="a"/>',
        "names an external DTD 'file:///etc/passwd'",
    ),
}


@pytest.mark.parametrize("case", sorted(DOCTYPES))
def test_doctype_with_entities_or_external_dtd_is_refused(case: str, tmp_path: Path):
    text, problem = DOCTYPES[case]
    with pytest.raises(XmlError) as info:
        parse_xml(text)
    assert info.value.element == "DOCTYPE" and problem in info.value.problem
    path = tmp_path / f"{case}.urdf"
    path.write_text(text)
    report = validate(path)
    assert [(f.layer, f.element) for f in report.errors] == [(1, "DOCTYPE")], report.format()
    with pytest.raises(ConversionError, match="DOCTYPE"):
        to_mjcf(path)
    assert main(["validate", str(path)]) == 2


def test_a_bare_doctype_is_accepted(tmp_path: Path):
    path = tmp_path / "arm.urdf"
    path.write_text(ARM.replace('<robot name="ur5e_arm">', '<!DOCTYPE robot>\n<robot name="a">'))
    assert validate(path, native=False).ok


@pytest.mark.parametrize(
    "text, element, problem",
    [
        ("<robot>" + "<x>" * (MAX_DEPTH + 1) + "</x>" * (MAX_DEPTH + 1) + "</robot>",
         "XML tree", f"nested more than {MAX_DEPTH}"),
        (f'<robot name="{"n" * (MAX_ATTRIBUTE_CHARS + 1)}"/>', "<robot> attribute 'name'",
         "characters long"),
        (b'<?xml version="1.0" encoding="no-such-codec"?><robot/>', "XML declaration",
         "cannot be decoded"),
        ('<robot name="\xff"/>'.encode("latin-1"), "XML at line 1, column 13",
         "not well-formed"),
        ("<robot><link", "XML at line 1, column 7", "not well-formed"),
    ],
)  # fmt: skip
def test_unsafe_or_broken_xml_gets_a_named_error(text, element: str, problem: str):
    with pytest.raises(XmlError) as info:
        parse_xml(text)
    assert info.value.element == element and problem in info.value.problem
    assert info.value.fix


def test_a_file_above_the_size_limit_is_not_read(tmp_path: Path):
    path = tmp_path / "big.urdf"
    with path.open("wb") as f:
        f.truncate(MAX_BYTES + 1)  # sparse: no disk space used
    with pytest.raises(XmlError, match="above the 8 MiB"):
        read_xml(path)


# --------------------------------------------------------------------------- hostile values

HOSTILE_VALUES = {
    "huge_offset": (
        ('<origin xyz="0 0 0.045" rpy="0 0 0"/>', '<origin xyz="0 -1e308 0.045" rpy="0 0 0"/>'),
        "link 'base_link'",
        "more than 10000 m from its frame",
    ),
    "size_ratio": (
        ('<cylinder radius="0.075" length="0.09"/>', '<cylinder radius="3.4e38" length="0.09"/>'),
        "link 'base_link'",
        "differ by more than a factor 1e+05",
    ),
    "overflowing_inertia": (
        ('ixx="0.008325" ixy="0"', 'ixx="0.008325" ixy="1.7976931348623157e308"'),
        "link 'base_link'",
        "is not positive definite",
    ),
    "self_mimic": (
        ('<joint name="ft_sensor_joint" type="fixed">',
         '<joint name="ft_sensor_joint" type="fixed"><mimic joint="ft_sensor_joint"/>'),
        "joint 'ft_sensor_joint'",
        "mimics itself",
    ),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(HOSTILE_VALUES))
def test_extreme_values_get_named_errors(case: str, tmp_path: Path):
    (old, new), element, problem = HOSTILE_VALUES[case]
    assert old in ARM
    path = tmp_path / "arm.urdf"
    path.write_text(ARM.replace(old, new, 1))
    report = validate(path)
    assert any(f.element == element and problem in f.problem for f in report.errors), (
        report.format()
    )
    with pytest.raises(ConversionError, match=problem.replace("+", r"\+")):
        to_mjcf(path)


# --------------------------------------------------------------------------- outside files


def _arm_with_mesh(tmp_path: Path, filename: str, tag: str = "mesh") -> Path:
    """The shipped arm with one visual on wrist_3_link pointing at ``filename``."""
    if tag == "mesh":
        shape = f'<geometry><mesh filename="{filename}"/></geometry>'
    else:
        shape = (
            '<geometry><sphere radius="0.01"/></geometry>'
            f'<material name="t"><texture filename="{filename}"/></material>'
        )
    marker = '<link name="wrist_3_link">'
    path = tmp_path / "urdf" / "arm.urdf"
    path.parent.mkdir(exist_ok=True)
    path.write_text(ARM.replace(marker, f"{marker}<visual>{shape}</visual>", 1))
    return path


@pytest.mark.parametrize(
    "filename",
    [
        "../outside/secret.stl",
        "file:///etc/hostname.stl",
        "package://../outside/secret.stl",
        "link_out/secret.stl",
    ],
)
@pytest.mark.parametrize("tag", ["mesh", "texture"])
def test_meshes_and_textures_outside_the_folders_are_refused_unread(
    filename: str, tag: str, tmp_path: Path
):
    (tmp_path / "outside").mkdir()
    (tmp_path / "outside" / "secret.stl").write_bytes(b"\0" * 84)
    path = _arm_with_mesh(tmp_path, filename, tag)
    (path.parent / "link_out").symlink_to(tmp_path / "outside")
    report = validate(path)
    problems = [f.problem for f in report.errors if f.element == "link 'wrist_3_link'"]
    assert any("outside" in p or "was not found" in p for p in problems), report.format()
    with pytest.raises(ConversionError):
        to_mjcf(path)


def test_package_search_is_bounded_and_takes_plain_names_only(tmp_path: Path):
    deep = tmp_path / "a" / "b" / "c" / "d" / "e"
    deep.mkdir(parents=True)
    (tmp_path / "pkg").mkdir()
    urdf = deep / "arm.urdf"
    assert find_package_dir("pkg", urdf, {}) is None  # five levels up: beyond the search
    assert find_package_dir("pkg", tmp_path / "a" / "arm.urdf", {}) == tmp_path / "pkg"
    for name in ("..", ".", "", "a/b"):
        assert find_package_dir(name, urdf, {}) is None
    with pytest.raises(AssetPathError, match="outside"):
        resolve_asset("package://pkg/../../secret.stl", urdf, {"pkg": str(tmp_path / "pkg")})


def test_the_audit_flags_reads_outside_and_ignores_writes_and_modules(tmp_path: Path):
    audit = _OpenAudit()
    inside = str(tmp_path / "arm.urdf")
    with audit.watching([str(tmp_path)]) as hits:
        audit("open", ("/etc/hostname", "r", os.O_RDONLY))
        audit("open", (inside, "rb", os.O_RDONLY))
        audit("open", ("/tmp/out.xml", "w", os.O_WRONLY | os.O_CREAT))
        audit("open", (os.__file__, "r", os.O_RDONLY))
    audit("open", ("/etc/passwd", "r", os.O_RDONLY))  # not watching
    assert hits == [os.path.realpath("/etc/hostname")]


# --------------------------------------------------------------------------- mutations


def _bases() -> dict[str, bytes]:
    return {"ur5e": ARM.encode()}


def test_mutants_are_reproducible_and_cover_every_kind():
    first = list(mutants(_bases(), 2 * len(KINDS), seed=7))
    again = list(mutants(_bases(), 2 * len(KINDS), seed=7))
    assert [m.data for m in first] == [m.data for m in again]
    assert {m.kind for m in first} == set(KINDS)
    assert mutant(_bases(), 5, seed=7) == first[5]
    other = list(mutants(_bases(), 2 * len(KINDS), seed=8))
    assert sum(a.data != b.data for a, b in zip(first, other, strict=True)) > len(KINDS)


@pytest.mark.slow
def test_seeded_mutations_get_named_errors_or_pass(tmp_path: Path):
    outcomes = run_fuzz(FUZZ_MUTATIONS, FUZZ_SEED, tmp_path)
    assert len(outcomes) == FUZZ_MUTATIONS
    for o in outcomes:
        what = f"mutant {o.index} ({o.kind} of {o.base}: {o.description})"
        assert [r.op for r in o.ops] == list(OPS), what
        for r in o.ops:
            assert r.status in ("pass", "named_error"), f"{what}: {r.op} {r.status}: {r.detail}"
            assert r.seconds < HANG_SECONDS, f"{what}: {r.op} took {r.seconds:.1f} s"
            assert r.status == "pass" or r.detail, f"{what}: {r.op} gave no message"
        assert not o.outside, f"{what} opened {o.outside}"
    counts = tally(outcomes)
    assert set(counts) == {*KINDS, "all"}
    assert counts["all"]["named_error"] > 0.5 * FUZZ_MUTATIONS
    assert all(counts[k][s] == 0 for k in KINDS for s in STATUSES if s in ("crash", "hang"))
    for kind in ("entity_expansion", "external_entity", "truncated", "cycle"):
        assert counts[kind]["named_error"] == counts[kind]["tried"], kind
