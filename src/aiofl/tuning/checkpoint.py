"""Checkpointing a tuning run after every generation, and replaying it on resume.

:func:`save_checkpoint` rewrites ``DIR/checkpoint.npz`` (:data:`CHECKPOINT`) atomically after
every generation of :func:`aiofl.tuning.search.tune`.  It holds every evaluated member
(unit-cube coordinates, engine metrics, divergence flag and time, the generation's wall
time) and the run's fingerprint (config, ``[tune]`` settings other than ``generations`` and
``chunks``, seed, initial population, objective coefficients).  :func:`load_checkpoint`
reads it back and refuses a checkpoint of another run or of another format.

Notes
-----
Resuming rebuilds the algorithm from the seed and *replays* the checkpointed generations:
:func:`check_replay` checks that each re-asked population equals the stored one bit for
bit, and the stored results are fed back instead of simulating; then the run carries on.
A resumed run therefore ends with exactly the result of an uninterrupted one, for every
pymoo algorithm (including CMA-ES, whose generator-based state cannot be pickled), and a
finished run can be extended by resuming with more generations.

A run that ends without a result (NSGA-II with no feasible design) has nothing worth
resuming: :func:`discard_new_checkpoint` removes the checkpoint it wrote (``aiofl tune``
calls it), and the folder if the run created it.
"""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L

__all__ = [
    "CHECKPOINT",
    "CHECKPOINT_FORMAT",
    "check_replay",
    "discard_new_checkpoint",
    "load_checkpoint",
    "save_checkpoint",
]

CHECKPOINT = "checkpoint.npz"
CHECKPOINT_FORMAT = 2  # 2: the scores of layout.SCORE_NAMES, "failed" (lost or diverged)


def save_checkpoint(path: Path, fingerprint: str, gens: list[dict[str, Any]]) -> None:
    """Write the generations so far to ``path`` (atomically, creating its directory as an
    aiofl output directory, :func:`aiofl.outputs.ensure_output_dir`).

    Each generation is a dict with arrays ``s`` (unit-cube members), ``metrics``,
    ``failed``, ``stopped_at`` and the float ``seconds``; other keys are not stored.

    Parameters
    ----------
    path
        The checkpoint file (``.npz``).
    fingerprint
        The run's fingerprint; :func:`load_checkpoint` refuses another run's file.
    gens
        The generations so far (above).
    """
    from aiofl.outputs import atomic_write_bytes, ensure_output_dir

    arrays: dict[str, Any] = {
        "meta": np.array(
            json.dumps(
                {"format": CHECKPOINT_FORMAT, "fingerprint": fingerprint, "generations": len(gens)}
            )
        )
    }
    for i, g in enumerate(gens):
        for key in ("s", "metrics", "failed", "stopped_at"):
            arrays[f"g{i}_{key}"] = g[key]
        arrays[f"g{i}_seconds"] = np.array(g["seconds"])
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    ensure_output_dir(path.parent)
    atomic_write_bytes(path, buf.getvalue())


def load_checkpoint(path: Path, fingerprint: str) -> list[dict[str, Any]]:
    """Read the generations stored in ``path`` (as :func:`save_checkpoint` wrote them).

    Raises :class:`aiofl.config.ConfigError`, naming the file, if it is empty, corrupt or
    unreadable, of another format, holds arrays of the wrong shape, or belongs to another
    run (its fingerprint differs from ``fingerprint``).
    """
    from aiofl.config import ConfigError

    if path.is_file() and path.stat().st_size == 0:
        raise ConfigError(f"checkpoint {path} is empty; delete it or drop --resume to start over")
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            if meta.get("format") != CHECKPOINT_FORMAT:
                raise ConfigError(f"checkpoint {path}: unsupported format {meta.get('format')}")
            if meta["fingerprint"] != fingerprint:
                raise ConfigError(
                    f"checkpoint {path} belongs to a different tuning run (config, [tune] "
                    "settings other than generations, or seed changed); use another --out "
                    "or drop --resume to start over"
                )
            gens = []
            for i in range(int(meta["generations"])):
                g = {k: data[f"g{i}_{k}"] for k in ("s", "metrics", "failed", "stopped_at")}
                g["seconds"] = float(data[f"g{i}_seconds"])
                _check_shapes(g, i + 1)
                gens.append(g)
            return gens
    except ConfigError:
        raise
    except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile) as exc:
        raise ConfigError(
            f"checkpoint {path} is corrupt or unreadable ({type(exc).__name__}: {exc}); "
            "delete it or drop --resume to start over"
        ) from None


def _check_shapes(g: dict[str, Any], generation: int) -> None:
    """Refuse a stored generation whose arrays do not fit together (a damaged file)."""
    s, m = g["s"], g["metrics"]
    n = s.shape[0] if s.ndim == 2 else -1
    # (n, 5) and (n,); a robust run stores every draw: (n, K+1, 5) and (n, K+1)
    ok = (
        n >= 0
        and m.ndim in (2, 3)
        and m.shape[0] == n
        and m.shape[-1] in (L.N_METRIC, L.N_SCORE)  # a custom evaluator gives the integrals
        and g["failed"].shape == m.shape[:-1]
        and g["stopped_at"].shape == m.shape[:-1]
        and g["failed"].dtype == np.bool_
        and all(np.issubdtype(a.dtype, np.floating) for a in (s, m, g["stopped_at"]))
    )
    if not ok:
        raise ValueError(f"generation {generation} has arrays of the wrong shape or type")


def check_replay(stored: dict[str, Any], s: NDArray[np.float64], generation: int) -> None:
    """Refuse to replay a stored generation the algorithm did not ask for again.

    ``stored`` is generation ``generation`` (counted from 1) as loaded by
    :func:`load_checkpoint`, ``s`` the population the algorithm asks for now (unit cube).
    Raises :class:`aiofl.config.ConfigError` unless they are equal bit for bit.

    Parameters
    ----------
    stored
        The stored generation, as :func:`load_checkpoint` loaded it.
    s
        The population the algorithm asks for now (unit cube).
    generation
        Its number, from 1 (for the message).
    """
    if stored["s"].shape != s.shape or not np.array_equal(stored["s"], s):
        from aiofl.config import ConfigError

        raise ConfigError(
            f"checkpoint replay diverged at generation {generation}: the algorithm asked "
            "for other members than were stored (different pymoo version?); start over "
            "without --resume"
        )


def discard_new_checkpoint(folder: Path, found: tuple[bool, bool]) -> None:
    """Remove ``folder/checkpoint.npz`` written by a run that ended without a result, and
    ``folder`` if the run created it and it holds nothing else but the aiofl marker.

    ``found`` is ``(folder existed, checkpoint existed)`` before the run: a checkpoint the
    run found (``--resume``) is kept, as is a folder that was there.
    """
    from aiofl.outputs import MARKER

    folder_existed, existed = found
    if existed:
        return
    (folder / CHECKPOINT).unlink(missing_ok=True)
    if not folder_existed and folder.is_dir() and {p.name for p in folder.iterdir()} <= {MARKER}:
        (folder / MARKER).unlink(missing_ok=True)
        folder.rmdir()
