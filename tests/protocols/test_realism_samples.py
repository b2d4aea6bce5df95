"""The realism samples are data that build scenes (SPEC §1, Table 1)."""

import tomllib
from importlib import resources

import pytest

from device import Scene


def samples():
    text = resources.files("protocols").joinpath("realism.toml").read_text(encoding="utf-8")
    return tomllib.loads(text)["samples"]


def test_eleven_samples_three_real():
    ids = [s["id"] for s in samples()]
    assert len(ids) == len(set(ids)) == 11
    real = [s["id"] for s in samples() if "material" in s["scene"]]
    assert sorted(real) == ["foam", "wood", "wood_on_foam"]


def test_paper_values():
    by = {s["id"]: s["scene"] for s in samples()}
    assert by["wood"]["material"]["stiffness"] == 70_000
    # Table 1's K ≈ 350 N/m of balsa on foam: the foam under the plate; the plate's stiff
    # contact in series leaves 348 N/m, within 1 %
    wof = by["wood_on_foam"]["material"]
    assert wof["support"]["stiffness"] == 350
    series = 1 / (1 / wof["stiffness"] + 1 / wof["support"]["stiffness"])
    assert series == pytest.approx(350, rel=0.01)
    assert by["foam"]["material"]["stiffness"] == 220
    assert by["firm_spring"]["spring"] == 680 and by["soft_spring"]["spring"] == 340
    assert by["pulse_firm"]["transient"] == {"kind": "pulse", "gain": 5.7, "duration": 0.020}
    assert by["sinusoid_soft"]["transient"]["frequency"] == 36.2  # what the study ran


@pytest.mark.parametrize("sample", samples(), ids=lambda s: s["id"])
def test_each_sample_builds_a_scene(sample):
    scene = Scene.from_dict({"name": sample["id"], **sample["scene"]})
    assert scene.name == sample["id"]
    if scene.kind == "library":
        assert scene.transient.source == "wood_on_foam" and scene.transient.attenuation == 0.8
