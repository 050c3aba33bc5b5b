"""Kernel libraries: the four formats, round trips and validation errors."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from gait_estimator import KernelLibrary, LibraryError, load_library, save_library
from gait_estimator.cli.app import main as cli_main
from gait_estimator.core.kernels import make_mode
from gait_estimator.io import library_io
from gait_estimator.io.library_io import DEFAULT_REFERENCE_RATE_HZ


def _same(a: KernelLibrary, b: KernelLibrary, atol: float = 0.0) -> None:
    assert a.mode_names == b.mode_names
    for ma, mb in zip(a.modes, b.modes, strict=True):
        assert ma.mode_id == mb.mode_id
        assert ma.sample_rate_hz == mb.sample_rate_hz
        np.testing.assert_allclose(ma.samples, mb.samples, rtol=0, atol=atol)


def test_reference_csv_directory(swge: Path) -> None:
    lib = load_library(swge / "kernels_able_bodied")
    assert lib.mode_names == ["Slow", "Med", "Fast", "RA", "RD", "SA", "SD"]
    assert [m.mode_id for m in lib.modes] == [1, 2, 3, 4, 5, 6, 7]
    assert list(lib.lengths) == [392, 313, 280, 283, 286, 318, 309]
    assert lib.sample_rate_hz == DEFAULT_REFERENCE_RATE_HZ
    first = np.loadtxt(swge / "kernels_able_bodied" / "Fast_AB_Reference.csv", delimiter=",", skiprows=2, usecols=range(4))
    np.testing.assert_array_equal(lib.mode("Fast").samples, first)
    assert "Notre Dame" in lib.provenance["license"]


def test_reference_yaml_directory(swge: Path) -> None:
    lib = load_library(swge / "kernels_prosthesis")
    assert lib.mode_names == ["Slow", "Med", "Fast", "RA", "RD", "SA", "SD"]
    doc = yaml.safe_load((swge / "kernels_prosthesis" / "SA_PR_Reference.yaml").read_text())
    np.testing.assert_array_equal(lib.mode("SA").samples[:, 2], doc["RShank"])
    assert lib.mode("SA").length == len(doc["percent"])


def test_single_reference_files(swge: Path) -> None:
    csv_lib = load_library(swge / "kernels_able_bodied" / "SD_AB_Reference.csv")
    assert csv_lib.mode_names == ["SD"] and csv_lib.modes[0].mode_id == 7
    yaml_lib = load_library(swge / "kernels_prosthesis" / "RA_PR_Reference.yaml")
    assert yaml_lib.mode_names == ["RA"] and yaml_lib.modes[0].mode_id == 4


@pytest.mark.parametrize(("bundled", "source"), [("able_bodied", "kernels_able_bodied"), ("prosthesis", "kernels_prosthesis")])
def test_bundled_libraries_equal_the_reference_data(swge: Path, bundled: str, source: str) -> None:
    lib = load_library(bundled)
    assert lib.name == bundled
    assert "Copyright (c) 2024 Robotics, Optimization, and Assistive Mobility Lab @ Notre Dame" in lib.provenance["license"]
    assert Path(lib.path).read_text().count("Notre Dame") >= 1
    _same(lib, load_library(swge / source), atol=1e-9)  # YAML keeps 9 decimals


@pytest.mark.parametrize("suffix", [".yaml", ".npz"])
def test_round_trip(tmp_path: Path, able_bodied: KernelLibrary, suffix: str) -> None:
    out = save_library(able_bodied, tmp_path / f"lib{suffix}")
    back = load_library(out)
    _same(able_bodied, back, atol=0.0)
    assert back.name == able_bodied.name
    assert back.provenance == able_bodied.provenance


class _FlowRow(list):
    """A kernel row, for PyYAML to write in flow style ``[a, b, c, d]``."""


class _FlowRowsDumper(library_io._YamlDumper):
    pass


_FlowRowsDumper.add_representer(
    _FlowRow, lambda dumper, row: dumper.represent_sequence("tag:yaml.org,2002:seq", list(row), flow_style=True)
)


def test_yaml_text_equals_pyyaml_dump(tmp_path: Path, able_bodied: KernelLibrary) -> None:
    """The kernel rows are formatted without PyYAML's representer (for speed): the file must be
    the text PyYAML itself writes (rows in flow style), for odd floats and names that need
    quoting too."""
    odd = able_bodied.modes[0].samples.copy()
    odd[0] = [1e-05, -2.5e-07, 123456789.123, -0.0]
    odd[1] = [1e16, 3e-9, 0.1, -1e-10]
    modes = (make_mode("a: b #1", odd, 230.0), make_mode("Ünïcode", np.ones((3, 4)), 230.0), *able_bodied.modes[1:])
    for lib in (able_bodied, KernelLibrary("odd 'name'", modes)):
        out = save_library(lib, tmp_path / "lib.yaml")
        doc = library_io.library_to_doc(lib)
        for md in doc["modes"]:
            md["samples"] = [_FlowRow(row) for row in md["samples"]]
        expected = yaml.dump(doc, Dumper=_FlowRowsDumper, sort_keys=False, width=120, allow_unicode=True)
        assert out.read_text(encoding="utf-8") == library_io._yaml_header(lib) + expected
        back = load_library(out)
        assert [m.name for m in back.modes] == [m.name for m in lib.modes]
        np.testing.assert_array_equal(back.modes[0].samples, np.round(lib.modes[0].samples, 9))


def test_large_library_npz_round_trip(tmp_path: Path, able_bodied: KernelLibrary) -> None:
    big = able_bodied.replicated(700)
    back = load_library(save_library(big, tmp_path / "big.npz"))
    assert len(back) == 700 and back.mode_names[-1] == big.mode_names[-1]
    np.testing.assert_array_equal(back.modes[699].samples, big.modes[699].samples)


def _write_doc(tmp_path: Path, mutate) -> Path:
    lib = KernelLibrary("t", (make_mode("A", np.ones((5, 4)), 100.0), make_mode("B", np.zeros((4, 4)), 100.0)))
    from gait_estimator.io.library_io import library_to_doc

    doc = library_to_doc(lib)
    for m in doc["modes"]:
        m["samples"] = [list(r) for r in m["samples"]]
    mutate(doc)
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump(doc))
    return p


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d["modes"][0].update(samples=[[1, 2, 3]] * 5, length=5), "shape"),
        (lambda d: d["modes"][0]["samples"][2].__setitem__(1, float("nan")), "non-finite value at sample 2"),
        (lambda d: d["modes"][1].update(name="A"), "duplicate mode name 'A'"),
        (lambda d: d["modes"][1].update(name="stand"), "mode name 'stand' is reserved"),
        (lambda d: d["modes"][0].update(name="unknown"), "mode name 'unknown' is reserved"),
        (lambda d: d["modes"][1].update(samples=[[1, 2, 3, 4]], length=1), "need at least 2"),
        (lambda d: d.pop("channels"), "missing metadata key 'channels'"),
        (lambda d: d["modes"][0].pop("sample_rate_hz"), "missing 'sample_rate_hz'"),
        (lambda d: d.update(format="something/else"), "unknown format"),
        (lambda d: d.update(format_version=99), "unsupported format_version"),
        (lambda d: d["modes"][1].update(sample_rate_hz=200.0), "differs from"),
        (lambda d: d["modes"][0].update(sample_rate_hz=-1), "invalid sample_rate_hz"),
        (lambda d: d["modes"][0].update(length=9), "says length 9"),
        (lambda d: d.update(channels=["a", "b", "c", "d"]), "channels"),
    ],
)
def test_validation_errors_name_the_file(tmp_path: Path, mutate, message: str) -> None:
    p = _write_doc(tmp_path, mutate)
    with pytest.raises(LibraryError) as err:
        load_library(p)
    text = str(err.value)
    assert str(p) in text and message in text
    assert "\n" not in text


def test_unknown_and_broken_files(tmp_path: Path) -> None:
    cases = {
        "lib.txt": "hello",
        "lib.yaml": "a: [1, 2\n",
        "other.yaml": "foo: 1\n",
        "lib.npz": "not a zip",
        "k.csv": "no header\n1,2,3,4\n",
    }
    for name, text in cases.items():
        p = tmp_path / name
        p.write_text(text)
        with pytest.raises(LibraryError, match=str(p)):
            load_library(p)
    with pytest.raises(LibraryError, match="no such file"):
        load_library(tmp_path / "missing.yaml")
    (tmp_path / "empty").mkdir()
    with pytest.raises(LibraryError, match="no reference kernel files"):
        load_library(tmp_path / "empty")


def test_reference_csv_with_wrong_row_count(tmp_path: Path, swge: Path) -> None:
    lines = (swge / "kernels_able_bodied" / "Med_AB_Reference.csv").read_text().splitlines()
    p = tmp_path / "Med.csv"
    p.write_text("\n".join(lines[:-5]) + "\n")
    with pytest.raises(LibraryError, match="Dimension says 313 samples but the file has 308 rows"):
        load_library(p)


def test_cli_kernels_show_and_convert(tmp_path: Path, swge: Path, capsys) -> None:
    assert cli_main(["kernels", "show", str(swge / "kernels_able_bodied")]) == 0
    out = capsys.readouterr().out
    assert "Slow" in out and "392" in out and "1.704" in out  # 392 samples / 230 Hz
    target = tmp_path / "pr.npz"
    assert cli_main(["kernels", "convert", str(swge / "kernels_prosthesis"), "--out", str(target), "--name", "pr"]) == 0
    lib = load_library(target)
    assert lib.name == "pr" and len(lib) == 7


def test_cli_errors_exit_2_with_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("format: gait_estimator/kernel_library\nformat_version: 1\n")
    proc = subprocess.run(
        [sys.executable, "-m", "gait_estimator.cli", "kernels", "show", str(bad)], capture_output=True, text=True
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0
    assert str(bad) in proc.stderr and "missing metadata key" in proc.stderr


def test_near_duplicates_finds_copies_by_shape_and_length(able_bodied: KernelLibrary) -> None:
    """Near copies: a kernel started at another phase with 0.3 deg added, or with one channel
    1.5 deg off (0.75 deg RMS over four channels); not near: 5 % longer, or one channel 2.5 deg
    off (1.25 deg RMS), unless that channel has no weight. The bundled modes are all distinct
    (the closest pair, Med and Fast, is 1.6 deg and 11 % apart)."""
    from gait_estimator.core.kernels import near_duplicates, resample_stride

    med = able_bodied.mode("Med")
    k = med.samples
    rate = med.sample_rate_hz
    variants = {
        "shifted": np.roll(k, 40, axis=0) + 0.3,
        "one_channel_1.5": k + np.array([1.5, 0, 0, 0]),
        "longer": resample_stride(k, round(1.05 * len(k))),
        "one_channel_2.5": k + np.array([0, 0, 2.5, 0]),
    }
    lib = KernelLibrary("v", (med, *(make_mode(n, v, rate) for n, v in variants.items())))
    near = near_duplicates(lib, 1.0, 0.02)
    assert near[0].tolist() == [True, True, True, False, False]
    assert (near == near.T).all()
    unweighted = near_duplicates(lib, 1.0, 0.02, np.array([1.0, 1.0, 0.0, 1.0]))
    assert unweighted[0, 4] and not unweighted[0, 3]
    assert (near_duplicates(able_bodied, 1.0, 0.02) == np.eye(len(able_bodied), dtype=bool)).all()
    assert near_duplicates(able_bodied, 1.7, 0.2)[1, 2] and not near_duplicates(able_bodied, 1.5, 0.2)[1, 2]


def _plain_pyyaml_load(p: Path) -> KernelLibrary:
    """The project YAML read by PyYAML alone (the specification of the fast row reader)."""
    return library_io._library_from_doc(library_io._read_yaml(p), p)


@pytest.mark.parametrize("row", [
    "- [1.5, -2.0, 3.25e-05, 4.0e+16]",  # what save_library writes
    "- [1, -2, 0, +7]",  # ints
    "- [010, 0x1F, 1_000.5, 2]",  # YAML 1.1 octal, hex, underscores: left to PyYAML
    "- [-0, 1.0, 2.0, 3.0]",  # -0 is the int 0 in YAML: left to PyYAML
    "- [.5, 1.0, 2.0, 3.0]",
    "- [1e-5, 1.0, 2.0, 3.0]",  # a string in YAML 1.1
    "- [1.0e5, 1.0, 2.0, 3.0]",  # a string too (the exponent needs a sign)
    "- [1.0, 2.0, 3.0]",  # three values
    "- [1.0, 2.0, 3.0, 4.0]  # a comment",
    "  - [1.0, 2.0, 3.0, 4.0]",  # rows indented below the key
])
def test_fast_yaml_rows_read_what_pyyaml_reads(tmp_path: Path, able_bodied: KernelLibrary, row: str) -> None:
    """Kernel rows in flow style are read without PyYAML's constructor (a 700-mode library in well
    under a second instead of ~10 s); every spelling gives what PyYAML gives, or the same error."""
    text = save_library(able_bodied, tmp_path / "lib.yaml").read_text(encoding="utf-8")
    lines = text.splitlines(keepends=True)
    first = next(i for i, line in enumerate(lines) if line.strip() == "samples:") + 3
    indent = lines[first][: len(lines[first]) - len(lines[first].lstrip())]
    if row.startswith("  "):  # indent every row of that block
        k = first - 3 + 1
        while lines[k].startswith(indent + "- ["):
            lines[k] = "  " + lines[k]
            k += 1
    lines[first] = indent + row + "\n"
    p = tmp_path / "edited.yaml"
    p.write_text("".join(lines), encoding="utf-8")
    try:
        expected = _plain_pyyaml_load(p)
    except LibraryError as exc:
        with pytest.raises(LibraryError) as err:
            load_library(p)
        assert str(err.value) == str(exc)
        return
    got = load_library(p)
    for a, b in zip(got.modes, expected.modes, strict=True):
        assert a.name == b.name and a.info == b.info and a.sample_rate_hz == b.sample_rate_hz
        np.testing.assert_array_equal(a.samples, b.samples)
        assert np.array_equal(np.signbit(a.samples), np.signbit(b.samples))


def test_large_yaml_library_reads_the_rows_fast(tmp_path: Path, able_bodied: KernelLibrary) -> None:
    big = able_bodied.replicated(70)
    p = save_library(big, tmp_path / "big.yaml")
    _, rows = library_io._read_yaml_with_rows(p)
    assert len(rows) == 70  # every block took the fast path
    got, expected = load_library(p), _plain_pyyaml_load(p)
    assert got.provenance == expected.provenance and got.name == expected.name
    for a, b in zip(got.modes, expected.modes, strict=True):
        np.testing.assert_array_equal(a.samples, b.samples)
