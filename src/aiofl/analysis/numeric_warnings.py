"""numpy's and scipy's RuntimeWarnings during an analysis, caught and said in one line.

An analysis evaluates the plant where a user's model may not be finite (a finite difference
reaching the maglev's x1 = 0, an orbit leaving the operating region); numpy then prints a
``RuntimeWarning`` pointing into the generated plant module in the cache, which tells a user
nothing.  :func:`numeric_warnings` collects them while an analysis runs (other warnings
pass through as usual) and :func:`warnings_note` says, once, how many there were, what
and where (the plant's functions, numpy, scipy or aiofl), e.g. ``3 numerical warnings while
analysing: divide by zero encountered in scalar divide (×3, in the plant's functions)``.
"""

from __future__ import annotations

import warnings
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["numeric_warnings", "warnings_note"]


@contextmanager
def numeric_warnings() -> Iterator[list[warnings.WarningMessage]]:
    """Record the warnings raised inside the block in the list it yields (for
    :func:`warnings_note`, which reads its RuntimeWarnings at any time); at the block's end
    the other warnings are shown as they would have been."""
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        try:
            yield seen
        finally:
            others = [w for w in seen if not issubclass(w.category, RuntimeWarning)]
    for w in others:  # outside the recording block: shown (or filtered) as usual
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)


def _where(filename: str) -> str:
    parts = Path(filename).parts
    if "plants" in parts and Path(filename).name.startswith("plant_"):
        return "the plant's functions"
    for package in ("scipy", "numpy", "aiofl"):
        if package in parts:
            return package
    return Path(filename).name


def warnings_note(caught: list[warnings.WarningMessage]) -> str | None:
    """One sentence on the RuntimeWarnings among ``caught`` (None when there are none)."""
    caught = [w for w in caught if issubclass(w.category, RuntimeWarning)]
    if not caught:
        return None
    counts = Counter((str(w.message), _where(w.filename)) for w in caught)
    items = [f"{msg} (×{n}, in {where})" for (msg, where), n in counts.most_common(4)]
    more = f"; {len(counts) - 4} more kinds" if len(counts) > 4 else ""
    return (
        f"{len(caught)} numerical warning(s) while analysing: {'; '.join(items)}{more}. "
        "They come from evaluating the loop where it is not finite (e.g. away from the "
        "operating point); a quantity computed from such values is reported as not analysed"
    )
