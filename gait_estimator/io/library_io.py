"""Reading and writing kernel libraries.

Formats, detected from the path:

* project YAML (``*.yaml``/``*.yml`` with ``format: gait_estimator/kernel_library``) - the
  human-readable form, one file per library;
* project NPZ (``*.npz``) - the same content in a compact binary form for large libraries;
* the reference implementation's kernel CSVs (a directory of files, or one file, whose first
  line is ``Name:Fast;ID:3;Dimension:4x280``);
* the reference implementation's per-mode YAML (``percent``, ``RThigh``, ``LThigh``,
  ``RShank``, ``LShank``; a directory of files, or one file).

The reference formats carry no sample rate: they get ``DEFAULT_REFERENCE_RATE_HZ`` (the paper's
"approximately 230 Hz").
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..core.channels import CHANNELS, N_CHANNELS
from ..core.errors import LibraryError
from ..core.kernels import REFERENCE_MODE_IDS, KernelLibrary, KernelMode, make_mode
from .atomic import atomic_write_text, atomic_write_with

FORMAT_TAG = "gait_estimator/kernel_library"
FORMAT_VERSION = 1
SAMPLE_DECIMALS = 9
"""Kernel samples are written to YAML rounded to this many decimals (degrees)."""
DEFAULT_REFERENCE_RATE_HZ = 230.0
"""Sample rate given to the reference kernels: the paper's "approximately 230 Hz"."""

_REF_YAML_KEYS = ("RThigh", "LThigh", "RShank", "LShank")
PAPER_CITATION = (
    "A. Posh, J. Li, P. M. Wensing, 'Simultaneous Locomotion Mode Classification and Continuous "
    "Gait Phase Estimation for Transtibial Prostheses'"
)

try:  # libyaml is several times faster when present
    _YamlLoader: Any = yaml.CSafeLoader
    _YamlDumper: Any = yaml.CSafeDumper
except AttributeError:  # pragma: no cover - depends on the PyYAML build
    _YamlLoader = yaml.SafeLoader
    _YamlDumper = yaml.SafeDumper


# ---------------------------------------------------------------------------------------------
# Detection and dispatch


def load_library(path: str | Path) -> KernelLibrary:
    """Read a kernel library in any supported format.

    Args:
        path: A project ``.yaml``/``.npz`` file, a reference CSV or per-mode YAML file, a
            directory of reference files, or the name of a bundled library
            (``able_bodied``, ``prosthesis``).

    Raises:
        LibraryError: one line naming the file and what is wrong with it.
    """
    p = Path(path)
    if not p.exists():
        from .resources import bundled_library_names, bundled_library_path

        if str(path) in bundled_library_names():
            return load_library(bundled_library_path(str(path)))
        raise LibraryError(f"{p}: no such file or directory, nor a bundled library "
                           f"({', '.join(bundled_library_names())})")
    if p.is_dir():
        return _load_reference_dir(p)
    suffix = p.suffix.lower()
    if suffix == ".npz":
        return _load_npz(p)
    if suffix == ".csv":
        mode = _load_reference_csv(p)
        return KernelLibrary(p.stem, (mode,), _reference_provenance(p), str(p))
    if suffix in (".yaml", ".yml"):
        doc = _put_rows(*_read_yaml_with_rows(p))
        if isinstance(doc, dict) and "format" in doc:
            return _library_from_doc(doc, p)
        if isinstance(doc, dict) and "percent" in doc:
            mode = _reference_yaml_mode(doc, p)
            return KernelLibrary(p.stem, (mode,), _reference_provenance(p), str(p))
        raise LibraryError(
            f"{p}: unknown YAML layout (expected 'format: {FORMAT_TAG}' or the reference "
            "per-mode keys 'percent, RThigh, LThigh, RShank, LShank')"
        )
    raise LibraryError(f"{p}: unknown library format '{suffix}' (use .yaml, .npz, .csv or a directory)")


def save_library(lib: KernelLibrary, path: str | Path) -> Path:
    """Write ``lib`` as project YAML (``.yaml``/``.yml``) or NPZ (``.npz``), by suffix.

    Atomic (``atomic.py``): the file is written beside ``path`` under a temporary name, fsynced
    and renamed over ``path``, so ``path`` holds the old or the new library, never a part."""
    p = Path(path)
    suffix = p.suffix.lower()
    doc = library_to_doc(lib, samples=False)
    if suffix == ".npz":
        samples = np.concatenate([m.samples for m in lib.modes])
        meta = np.array(json.dumps(doc))
        atomic_write_with(
            p, lambda f: np.savez_compressed(f, meta=meta, samples=samples, lengths=lib.lengths), binary=True
        )
    elif suffix in (".yaml", ".yml"):
        atomic_write_text(p, _yaml_header(lib) + _yaml_body(doc, lib))
    else:
        raise LibraryError(f"{p}: cannot write format '{suffix}' (use .yaml or .npz)")
    return p


# ---------------------------------------------------------------------------------------------
# Project format


def library_to_doc(lib: KernelLibrary, samples: bool = True) -> dict[str, Any]:
    """The project-format document (plain Python types) for ``lib``; without the kernels'
    ``samples`` if ``samples`` is False (the NPZ form stores them as an array)."""
    doc = {
        "format": FORMAT_TAG,
        "format_version": FORMAT_VERSION,
        "name": lib.name,
        "units": "deg",
        "channels": list(CHANNELS),
        "provenance": _plain(dict(lib.provenance)),
        "modes": [
            {
                "name": m.name,
                "id": m.mode_id,
                "sample_rate_hz": m.sample_rate_hz,
                "length": m.length,
                "info": _plain(dict(m.info)),
            }
            for m in lib.modes
        ],
    }
    if samples:
        for md, m in zip(doc["modes"], lib.modes, strict=True):
            md["samples"] = _rounded_rows(m)
    return doc


def _rounded_rows(mode: KernelMode) -> list[list[float]]:
    """The kernel's samples as written to YAML: rows of floats rounded to SAMPLE_DECIMALS."""
    return [[round(v, SAMPLE_DECIMALS) for v in row] for row in mode.samples.tolist()]


def _library_from_doc(doc: dict[str, Any], p: Path, samples: list[np.ndarray] | None = None) -> KernelLibrary:
    if doc.get("format") != FORMAT_TAG:
        raise LibraryError(f"{p}: unknown format {doc.get('format')!r} (expected {FORMAT_TAG!r})")
    version = doc.get("format_version")
    if version != FORMAT_VERSION:
        raise LibraryError(f"{p}: unsupported format_version {version!r} (this version reads {FORMAT_VERSION})")
    for key in ("name", "channels", "units", "modes"):
        if key not in doc:
            raise LibraryError(f"{p}: missing metadata key '{key}'")
    if list(doc["channels"]) != list(CHANNELS):
        raise LibraryError(f"{p}: channels {doc['channels']} differ from the required order {list(CHANNELS)}")
    if doc["units"] != "deg":
        raise LibraryError(f"{p}: units {doc['units']!r} not supported (kernels are stored in 'deg')")
    if not isinstance(doc["modes"], list) or not doc["modes"]:
        raise LibraryError(f"{p}: 'modes' must be a non-empty list")
    modes = []
    for i, md in enumerate(doc["modes"]):
        if not isinstance(md, dict):
            raise LibraryError(f"{p}: mode #{i} is not a mapping")
        for key in ("name", "sample_rate_hz") + (() if samples is not None else ("samples",)):
            if key not in md:
                raise LibraryError(f"{p}: mode #{i} ({md.get('name', '?')}) is missing '{key}'")
        raw = samples[i] if samples is not None else md["samples"]
        try:
            arr = np.array(raw, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise LibraryError(f"{p}: mode {md['name']!r} samples are not an N x {N_CHANNELS} table ({exc})") from None
        if "length" in md and arr.ndim == 2 and md["length"] != arr.shape[0]:
            raise LibraryError(f"{p}: mode {md['name']!r} says length {md['length']} but has {arr.shape[0]} samples")
        try:
            rate = float(md["sample_rate_hz"])
        except (TypeError, ValueError):
            raise LibraryError(f"{p}: mode {md['name']!r} has invalid sample_rate_hz {md['sample_rate_hz']!r}") from None
        modes.append(make_mode(md["name"], arr, rate, int(md.get("id", 0) or 0), md.get("info") or {}))
    return KernelLibrary(str(doc["name"]), tuple(modes), dict(doc.get("provenance") or {}), str(p))


def _load_npz(p: Path) -> KernelLibrary:
    try:
        with np.load(p, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            flat = np.asarray(z["samples"], dtype=np.float64)
            lengths = np.asarray(z["lengths"], dtype=np.int64)
    except (OSError, ValueError, KeyError) as exc:
        raise LibraryError(f"{p}: not a readable kernel library .npz ({exc})") from None
    if flat.ndim != 2 or lengths.sum() != flat.shape[0] or len(lengths) != len(meta.get("modes", [])):
        raise LibraryError(f"{p}: samples/lengths arrays do not match the mode list")
    parts = np.split(flat, np.cumsum(lengths)[:-1])
    return _library_from_doc(meta, p, samples=parts)


# ---------------------------------------------------------------------------------------------
# Reference (SWGE) formats

_HEADER_RE = re.compile(r"^\s*Name:(?P<name>[^;]+);ID:(?P<id>-?\d+);Dimension:(?P<rows>\d+)x(?P<cols>\d+)")


def _reference_provenance(p: Path) -> dict[str, Any]:
    prov: dict[str, Any] = {
        "source": f"{p.name}: kernel files in the reference implementation's format",
        "built_by": "gait-estimator kernels convert (reference-format import, values unchanged)",
        "sample_rate_note": (
            f"reference files carry no rate; {DEFAULT_REFERENCE_RATE_HZ:g} Hz is the paper's "
            "'approximately 230 Hz' XSENS rate"
        ),
        "citation": PAPER_CITATION,
    }
    for parent in (p if p.is_dir() else p.parent, *p.resolve().parents):
        lic = parent / "LICENSE"
        if lic.is_file():
            prov["license"] = lic.read_text(encoding="utf-8").strip()
            break
    return prov


def _load_reference_csv(p: Path) -> KernelMode:
    try:
        with p.open(encoding="utf-8") as f:
            header = f.readline()
            f.readline()  # channel names
            rows = [line for line in f if line.strip()]
    except (OSError, UnicodeDecodeError) as exc:
        raise LibraryError(f"{p}: cannot read ({exc})") from None
    m = _HEADER_RE.match(header)
    if not m:
        raise LibraryError(f"{p}: first line is not a reference kernel header 'Name:..;ID:..;Dimension:4xN'")
    n_ch, n = int(m["rows"]), int(m["cols"])
    if n_ch != N_CHANNELS:
        raise LibraryError(f"{p}: Dimension says {n_ch} channels, expected {N_CHANNELS}")
    if len(rows) != n:
        raise LibraryError(f"{p}: Dimension says {n} samples but the file has {len(rows)} rows")
    try:
        data = [[float(v) for v in line.split(",")[:N_CHANNELS]] for line in rows]
    except ValueError as exc:
        raise LibraryError(f"{p}: non-numeric value in kernel rows ({exc})") from None
    if any(len(r) != N_CHANNELS for r in data):
        raise LibraryError(f"{p}: a kernel row has fewer than {N_CHANNELS} values")
    return make_mode(m["name"].strip(), data, DEFAULT_REFERENCE_RATE_HZ, int(m["id"]))


def _reference_yaml_mode(doc: dict[str, Any], p: Path) -> KernelMode:
    missing = [k for k in ("percent", *_REF_YAML_KEYS) if k not in doc]
    if missing:
        raise LibraryError(f"{p}: missing key(s) {', '.join(missing)}")
    try:
        cols = [np.asarray(doc[k], dtype=np.float64) for k in _REF_YAML_KEYS]
        percent = np.asarray(doc["percent"], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise LibraryError(f"{p}: non-numeric kernel values ({exc})") from None
    lengths = {len(c) for c in cols} | {len(percent)}
    if len(lengths) != 1 or any(c.ndim != 1 for c in cols):
        raise LibraryError(f"{p}: percent/RThigh/LThigh/RShank/LShank have different lengths {sorted(lengths)}")
    if len(percent) >= 2 and not np.all(np.diff(percent) > 0):
        raise LibraryError(f"{p}: 'percent' is not strictly increasing")
    name = p.stem.split("_")[0]
    return make_mode(name, np.stack(cols, axis=1), DEFAULT_REFERENCE_RATE_HZ, REFERENCE_MODE_IDS.get(name, 0))


def _load_reference_dir(d: Path) -> KernelLibrary:
    modes: list[KernelMode] = []
    for f in sorted(d.iterdir()):
        suffix = f.suffix.lower()
        if suffix == ".csv":
            modes.append(_load_reference_csv(f))
        elif suffix in (".yaml", ".yml"):
            doc = _read_yaml(f)
            if isinstance(doc, dict) and "percent" in doc:
                modes.append(_reference_yaml_mode(doc, f))
    if not modes:
        raise LibraryError(f"{d}: directory holds no reference kernel files (*.csv or per-mode *.yaml)")
    modes.sort(key=lambda m: (m.mode_id == 0, m.mode_id, m.name))
    return KernelLibrary(d.name, tuple(modes), _reference_provenance(d), str(d))


# ---------------------------------------------------------------------------------------------
# YAML helpers


def _read_yaml(p: Path) -> Any:
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise LibraryError(f"{p}: cannot read ({exc})") from None
    return _parse_yaml(text, p)


def _parse_yaml(text: str, p: Path) -> Any:
    try:
        return yaml.load(text, Loader=_YamlLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise LibraryError(f"{p}: invalid YAML{where}") from None


# A ``samples:`` key followed by flow rows of four plain numbers, all at one indentation, and by
# no further line of that sequence (as save_library writes them): PyYAML's Python constructor
# takes ~10 s for the ~900,000 numbers of a 700-mode library, this reads them in a fraction of
# that. NUMBER is the subset of YAML 1.1 numbers whose value float() gives exactly (no leading
# zeros, underscores, signless exponents, -0); any other spelling leaves the block to PyYAML.
_NUMBER = r"[-+]?(?:0|[1-9][0-9]*)\.[0-9]*(?:[eE][-+][0-9]+)?|0|[-+]?[1-9][0-9]*"
_ROW = rf"- \[ *(?:{_NUMBER}) *, *(?:{_NUMBER}) *, *(?:{_NUMBER}) *, *(?:{_NUMBER}) *\][ \t]*\r?\n"
_ROWS_BLOCK = re.compile(
    rf"^(?P<ind> *)samples:[ \t]*\r?\n(?P<rows>(?P<ri>(?P=ind) *){_ROW}(?:(?P=ri){_ROW})*)(?!(?P=ind)[ \t-])",
    re.MULTILINE,
)
_ROWS_TAG = "@rows "


def _read_yaml_with_rows(p: Path) -> tuple[Any, list[np.ndarray]]:
    """The YAML document of ``p`` with every plain ``samples:`` block of flow rows (see
    _ROWS_BLOCK) read by numpy: the document holds ``'@rows K'`` there, and the K-th array of
    the list its rows (k, 4)."""
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise LibraryError(f"{p}: cannot read ({exc})") from None
    rows: list[np.ndarray] = []

    def slot(match: re.Match[str]) -> str:
        values = match.group("rows").replace("- [", "").replace("]", ",").split(",")[:-1]  # validated: numbers only
        rows.append(np.array(list(map(float, values)), dtype=np.float64).reshape(-1, N_CHANNELS))
        return f"{match.group('ind')}samples: '{_ROWS_TAG}{len(rows) - 1}'\n"

    fast = _ROWS_BLOCK.sub(slot, text) if "samples:" in text else text
    return _parse_yaml(fast, p), rows


def _put_rows(doc: Any, rows: list[np.ndarray]) -> Any:
    """Put the rows read by _read_yaml_with_rows back where the project document holds their tag."""
    modes = doc.get("modes") if rows and isinstance(doc, dict) else None
    for md in modes if isinstance(modes, list) else ():
        raw = md.get("samples") if isinstance(md, dict) else None
        if isinstance(raw, str) and raw.startswith(_ROWS_TAG) and raw[len(_ROWS_TAG):].isdigit():
            md["samples"] = rows[int(raw[len(_ROWS_TAG):])]
    return doc


_SAMPLES_SLOT = re.compile(r"^( *)samples: '?@samples (\d+)@'?$", re.MULTILINE)


def _yaml_body(doc: dict[str, Any], lib: KernelLibrary) -> str:
    """``yaml.dump`` of the library document (without samples) with ``lib``'s kernel rows, rounded
    to SAMPLE_DECIMALS, in flow style (``- [a, b, c, d]``): the text ``library_to_doc(lib)``
    dumps. The rows (thousands of floats) are formatted here and put where placeholders stood
    (``doc`` gets the placeholders), because passing each float through PyYAML's Python
    representer makes saving a library several times slower."""
    for k, md in enumerate(doc["modes"]):
        md["samples"] = f"@samples {k}@"
    text = yaml.dump(doc, Dumper=_YamlDumper, sort_keys=False, width=120, allow_unicode=True)

    def block(match: re.Match[str]) -> str:
        indent = match.group(1)
        rows = _rounded_rows(lib.modes[int(match.group(2))])
        lines = (f"{indent}- [{', '.join(_yaml_float(v) for v in row)}]" for row in rows)
        return f"{indent}samples:\n" + "\n".join(lines)

    return _SAMPLES_SLOT.sub(block, text)


def _yaml_float(value: float) -> str:
    """A finite float as PyYAML's SafeRepresenter writes it (a dot before any exponent)."""
    text = repr(value)
    return text.replace("e", ".0e") if "e" in text and "." not in text else text


def _yaml_header(lib: KernelLibrary) -> str:
    lines = [
        f"# gait_estimator kernel library '{lib.name}': {len(lib)} modes,",
        "# samples in degrees, columns " + ", ".join(CHANNELS) + ", row 0 = right heel strike.",
    ]
    lic = str(lib.provenance.get("license", ""))
    if lic:
        lines.append("#")
        lines.extend(("# " + line).rstrip() for line in lic.splitlines())
    return "\n".join(lines) + "\n"


def _plain(value: Any) -> Any:
    """Convert numpy scalars/arrays inside metadata to plain Python for YAML/JSON."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value
