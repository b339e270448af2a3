"""Contact-force columns of the post-processor's tables (docs/model.md §9; paper SI
"Contact Forces", Table 2, Table S3, Fig. 6h).

Two kinds, both in N:

* ``F_<class>_<axis>_N``: the generalised forces on the cell periods that a job stores
  with ``[store] contact_forces = true`` (``CellModel.contact_forces_by_class``), rows
  the stitch's contact classes (``contact_classes``: a pattern's include ``mirrored``);
* ``pair_F_<class>_<axis>_N``: the paper's contact forces, unweighted pair forces
  between sampled yarn points (``CellModel.contact_pair_forces_by_class``), computed
  here from the stored zero-force state, rows the stitch's contact classes (the paper's
  :data:`~knitsweep.stitches.TRANSLATION_CLASSES` for stockinette; a pattern's
  ``MIRROR_CLASSES`` over its mirrored images). Fig. 6h's sums and their ratio
  ``force_ratio_xy`` are defined on the paper's classes, so they stay empty for a
  pattern, whose column neighbours fall in two classes (same column and mirrored).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..config import Fidelity, StitchParams
from ..stitches import TRANSLATION_CLASSES as CONTACT_CLASSES


def pair_columns(classes: tuple[str, ...] = CONTACT_CLASSES) -> tuple[str, ...]:
    """Columns of the pair forces by class (``CellModel.contact_pair_forces_by_class``,
    unweighted: the paper's Table S3 quantity), rows ``classes`` (the stitch's)."""
    return tuple(f"pair_F_{c}_{a}_N" for c in classes for a in "xyz")


def fig6h_forces(f: np.ndarray) -> tuple[float, float, float | None]:
    """Fig. 6h's sums of forces by class (5, 3): (x force of self + same row, y force of
    NN + NNN column, |x|/|y| or None)."""
    row = dict(zip(CONTACT_CLASSES, f, strict=True))
    widen_x = float(row["self"][0] + row["same_row"][0])
    column_y = float(row["nn_column"][1] + row["nnn_column"][1])
    return widen_x, column_y, abs(widen_x) / abs(column_y) if column_y != 0.0 else None


def contact_classes(meta: Mapping[str, Any]) -> tuple[str, ...]:
    """The contact classes (rows of the stored forces) of a task's stitch."""
    from ..stitches import DEFAULT_STITCH, get_stitch

    return get_stitch(str(meta.get("stitch", DEFAULT_STITCH))).contact_classes


def force_columns(forces: Any, classes: tuple[str, ...] = CONTACT_CLASSES) -> dict[str, Any]:
    """Stored generalised contact forces (5, 3) at zero strain → flat columns
    ``F_<class>_<axis>_N`` (rows ``classes``: the stitch's, ``contact_classes``), totals
    over the classes and their version of the Fig. 6h ratio,
    ``generalised_force_ratio_xy`` = |F_x(self) + F_x(same row)| / |F_y(NN) + F_y(NNN)|
    (not the paper's quantity: see :func:`pair_force_columns`; None for a pattern with
    mirrored images, whose column classes are not the paper's)."""
    columns = tuple(f"F_{c}_{a}_N" for c in classes for a in "xyz")
    keys = (*columns, "F_x_N", "F_y_N", "F_z_N", "generalised_force_ratio_xy")
    if forces is None:
        return dict.fromkeys(keys)
    f = np.asarray(forces, dtype=float).reshape(len(classes), 3)
    out: dict[str, Any] = dict(zip(columns, map(float, f.ravel()), strict=True))
    fx, fy, fz = (float(v) for v in f.sum(axis=0))
    out |= {"F_x_N": fx, "F_y_N": fy, "F_z_N": fz}
    translated = tuple(classes) == tuple(CONTACT_CLASSES)
    out["generalised_force_ratio_xy"] = fig6h_forces(f)[2] if translated else None
    return out


FIG6H_KEYS = ("pair_F_x_self_row_N", "pair_F_y_column_N", "force_ratio_xy")


def pair_keys(classes: tuple[str, ...] = CONTACT_CLASSES) -> tuple[str, ...]:
    """The pair-force columns of a stitch whose contact classes are ``classes``."""
    return (*pair_columns(classes), *FIG6H_KEYS)


PAIR_KEYS = pair_keys()
"""Stockinette's pair-force columns."""


def pair_force_columns(state: np.ndarray | None, meta: Mapping[str, Any],
                        fidelity: Fidelity) -> dict[str, Any]:  # fmt: skip
    """The paper's contact forces at zero strain (SI "Contact Forces", Table S3, Fig.
    6h): unweighted pair forces by class of the zero-force state (N; positive extends
    the fabric; rows the stitch's classes, ``contact_classes``), and, on the paper's
    classes, ``force_ratio_xy`` = |x force of self + same-row contacts| / |y force of
    NN + NNN same-column contacts| (paper: "the sum of the self contacts and same-row
    contacts ... become larger than the NNN same-column and NN same-column contacts in
    the y-direction, shown in Fig. 6h"); None for a pattern's."""
    classes = contact_classes(meta)
    if state is None:
        return dict.fromkeys(pair_keys(classes))
    from ..model import CellModel  # numba: only for files that store the states

    f = CellModel(StitchParams.from_flat(meta), fidelity).contact_pair_forces_by_class(state)
    out: dict[str, Any] = dict(zip(pair_columns(classes), map(float, f.ravel()), strict=True))
    if tuple(classes) != tuple(CONTACT_CLASSES):
        return out | dict.fromkeys(FIG6H_KEYS)
    fx, fy, ratio = fig6h_forces(f)
    return out | dict(zip(FIG6H_KEYS, (fx, fy, ratio), strict=True))


def job_fidelity(root: Mapping[str, Any]) -> Fidelity:
    """The job's fidelity (its contact sampling sets the pair forces), default if the
    file does not say."""
    try:
        return Fidelity(**json.loads(str(root.get("job_json", "{}")))["fidelity"])
    except (KeyError, TypeError, ValueError, json.JSONDecodeError):
        return Fidelity()
