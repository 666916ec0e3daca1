"""``mjx-arm arm --check`` draws a picture only when asked, and says where it went."""

from __future__ import annotations

from pathlib import Path

from mjx_arm.cli import EXIT_OK, main
from mjx_arm.paths import asset


def test_check_writes_no_picture_unasked_and_names_the_one_asked_for(
    tmp_path: Path, monkeypatch, capsys
) -> None:
    monkeypatch.chdir(tmp_path)
    urdf = str(asset("ur5e.urdf"))
    assert main(["arm", urdf, "--check"]) == EXIT_OK
    out = capsys.readouterr().out
    assert list(tmp_path.iterdir()) == []  # nothing written into the working directory
    assert "wrote" not in out and "--picture P.png" in out
    picture = tmp_path / "pictures" / "ur5e.png"
    assert main(["arm", urdf, "--check", "--picture", str(picture)]) == EXIT_OK
    out = capsys.readouterr().out
    assert picture.read_bytes()[:4] == b"\x89PNG"
    assert f"wrote the picture of the home pose over the task area to {picture}" in out
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["pictures", "ur5e.png"]
