"""The authors' file formats (sabetta/jammed-knits), so their users can migrate.

* Init files: the numbers of a state, one per line (stockinette: 30, docs/model.md §2).
* Config files: only lines starting with ``*`` count, as ``*key value [unit]``
  (docs/model.md §10). Their units are internal (N, mm, B/2); ``read_authors_config``
  converts them to knitsweep's user-facing ``StitchParams``.

Reading and writing them goes through ``util.safe_files`` (bounded reads, atomic
replacement, no writing through links).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from .config import StitchParams
from .errors import InputError, describe_validation_error, did_you_mean
from .quantities import PARAMETER_NAMES
from .stitches import DEFAULT_STITCH, Stitch, get_stitch
from .util.safe_files import read_text, replace_file

MAX_TEXT_BYTES = 1_000_000
"""State and config files are a few hundred bytes; anything past this is not one."""
MAX_STATE_VALUE = 1e4
"""|entry| of a state (mm or rad) beyond which a file is not a stitch's state."""


def read_state(path: str | Path, stitch: Stitch | str = DEFAULT_STITCH) -> np.ndarray:
    """Read a state file of ``stitch`` (one number per line: 30 for stockinette);
    errors name the file and the line."""
    stitch = get_stitch(stitch) if isinstance(stitch, str) else stitch
    n = stitch.n_state
    path = Path(path)
    lines = read_text(path, "state file", MAX_TEXT_BYTES).splitlines()
    values = []
    for no, line in enumerate(lines, 1):
        text = line.strip()
        if not text:
            continue
        try:
            v = float(text)
        except ValueError:
            raise InputError(f"state file {path} line {no}: {text!r} is not a number") from None
        if not math.isfinite(v):
            raise InputError(f"state file {path} line {no}: {text!r} is not finite")
        if abs(v) > MAX_STATE_VALUE:
            raise InputError(f"state file {path} line {no}: {text!r}: |value| must be <= "
                             f"{MAX_STATE_VALUE:g} (mm or rad)")  # fmt: skip
        values.append(v)
    if len(values) != n:
        raise InputError(f"state file {path}: expected {n} numbers for a {stitch.name} state, "
                         f"found {len(values)}")  # fmt: skip
    x = np.array(values)
    if x[-2] <= 0 or x[-1] <= 0:
        raise InputError(f"state file {path}: the cell periods a_x, a_y (lines {n - 1}, {n}) "
                         "must be > 0")  # fmt: skip
    return x


def write_state(path: str | Path, x: np.ndarray) -> None:
    """Write a state one number per line, exactly round-tripping every float."""
    x = np.asarray(x, dtype=float)
    if x.ndim != 1 or x.size < 2:
        raise ValueError(f"a state is a vector ending with the periods, got shape {x.shape}")
    replace_file(Path(path), "".join(f"{float(v)!r}\n" for v in x).encode())


def shipped_state(index: int = 1, stitch: str = DEFAULT_STITCH) -> np.ndarray:
    """One of the starting states shipped with ``stitch`` (stockinette: the authors'
    Init_1 … Init_7)."""
    return get_stitch(stitch).start(index)


@dataclass(frozen=True)
class AuthorsConfig:
    """An authors' config file, converted: the physics plus their run settings."""

    params: StitchParams
    samples_per_segment: int | None
    ftol: float | None
    sweep_direction: str | None
    step_size_mm: float | None
    init_dimension_mm: float | None
    final_dimension_mm: float | None
    init_file: str | None
    output_prefix: str | None


# key -> (StitchParams field, factor from their units to ours)
_PARAM_KEYS = {p.authors_key: (p.field, p.authors_factor) for p in PARAMETER_NAMES.values()
               if p.authors_key}  # fmt: skip
_FLOAT_KEYS = {"ftol", "step_size", "init_dimension", "final_dimension"}
_OTHER_KEYS = {"interactions_per_segment", "sweep_direction", "init_file", "output_prefix"}
KNOWN_KEYS = tuple(sorted(set(_PARAM_KEYS) | _FLOAT_KEYS | _OTHER_KEYS))


def read_authors_config(path: str | Path) -> AuthorsConfig:
    """Parse an authors' ``*key value [unit]`` config file; unknown keys are errors."""
    path = Path(path)
    text = read_text(path, "config file", MAX_TEXT_BYTES)
    raw: dict[str, tuple[str, int]] = {}
    for no, line in enumerate(text.splitlines(), 1):
        words = line.split()
        if not words or not words[0].startswith("*"):
            continue
        key = words[0][1:]
        if key not in KNOWN_KEYS:
            raise InputError(
                f"config file {path} line {no}: unknown key '*{key}'{did_you_mean(key, KNOWN_KEYS)}"
            )
        if len(words) < 2:
            raise InputError(f"config file {path} line {no}: '*{key}' has no value")
        raw[key] = (words[1], no)

    def number(key: str) -> float | None:
        if key not in raw:
            return None
        word, no = raw[key]
        try:
            return float(word)
        except ValueError:
            raise InputError(
                f"config file {path} line {no}: *{key} = {word!r} is not a number"
            ) from None

    fields = {}
    for key, (name, factor) in _PARAM_KEYS.items():
        v = number(key)
        if v is not None:
            fields[name] = v * factor
    try:
        params = StitchParams(**fields)
    except ValidationError as e:
        raise InputError(f"config file {path}: {describe_validation_error(e)}") from None
    samples = number("interactions_per_segment")
    if samples is not None and not (math.isfinite(samples) and samples == int(samples)):
        raise InputError(f"config file {path}: *interactions_per_segment must be an integer")
    direction = raw.get("sweep_direction", (None, 0))[0]
    if direction is not None:
        direction = "y" if direction.lower() == "y" else "x"  # as the reference reads it
    return AuthorsConfig(
        params=params,
        samples_per_segment=None if samples is None else int(samples),
        ftol=number("ftol"),
        sweep_direction=direction,
        step_size_mm=number("step_size"),
        init_dimension_mm=number("init_dimension"),
        final_dimension_mm=number("final_dimension"),
        init_file=raw.get("init_file", (None, 0))[0],
        output_prefix=raw.get("output_prefix", (None, 0))[0],
    )
