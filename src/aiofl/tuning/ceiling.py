r"""``[tune] omega0_ceiling = true`` (or ``aiofl tune --omega0-ceiling``): the observer
bandwidth's search bound clipped to what the rig allows.

:func:`clip_to_ceiling` computes the config's ω0 ceiling
(:func:`aiofl.analysis.observer_bandwidth.config_ceiling`: the sampling, delay and noise
caps, the binding one) and lowers ``tune.parameters."eso.omega0".hi`` to it, so the search
never proposes an observer faster than the sample time, the loop delay and the sensor's
noise allow.  The noise cap is taken at the config's ω_c when ``sef.omega_c`` is not tuned
(the search moves ω0 alone), else at the config's ratio ω0/ω_c.  It says what it did in
one sentence (printed by ``aiofl tune`` and ``--check``); a ceiling at or below the
bound's ``lo`` is refused (no search space left), as is the setting without ``eso.omega0``
among the tuned parameters (with Kalman gains ω0 is derived from ``eso.q``/``eso.r`` and
not clipped here).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # pragma: no cover
    from aiofl.config import RunConfig
    from aiofl.tuning.space import TuneSettings

__all__ = ["clip_to_ceiling"]

_NAME = "eso.omega0"


def clip_to_ceiling(
    cfg: RunConfig, settings: TuneSettings, source: str = ""
) -> tuple[TuneSettings, tuple[str, ...]]:
    """``settings`` with ``eso.omega0``'s upper bound clipped to the config's ω0 ceiling,
    and the sentence saying so (none when ``omega0_ceiling`` is off).  Raises
    :class:`aiofl.config.ConfigError` naming ``tune.omega0_ceiling`` when it cannot apply.

    Parameters
    ----------
    cfg
        The tuned run config.
    settings
        Its ``[tune]`` settings.
    source
        The config's name, for the message.

    Returns
    -------
    settings : TuneSettings
    notes : tuple of str
    """
    from aiofl.analysis.observer_bandwidth import config_ceiling
    from aiofl.config import ConfigError

    if not settings.omega0_ceiling:
        return settings, ()
    where = f"invalid [tune]{' of ' + source if source else ''}: tune.omega0_ceiling = true"
    bounds = settings.parameters.get(_NAME)
    if bounds is None:
        raise ConfigError(
            f'{where} clips the search bound of "{_NAME}", which is not tuned; allowed: '
            f'tune "{_NAME}" (with Kalman gains omega0 is derived from eso.q/eso.r)'
        )
    # a search that tunes omega0 but not omega_c moves omega0 at the design's omega_c
    ceiling = config_ceiling(cfg, hold_omega_c="sef.omega_c" not in settings.parameters)
    cap = ceiling.binding
    if cap is None:
        return settings, (
            f"omega0 ceiling: no cap applies (continuous, no delay, noise-free); "
            f'"{_NAME}" bounds kept [{bounds.lo:g}, {bounds.hi:g}] rad/s',
        )
    w = cap.omega0
    if w >= bounds.hi:
        return settings, (
            f'omega0 ceiling {w:.4g} rad/s ({cap.name}) is above "{_NAME}".hi = {bounds.hi:g}: '
            "bounds kept",
        )
    if not w > bounds.lo:
        raise ConfigError(
            f"{where}: the omega0 ceiling {w:.4g} rad/s ({cap.name}: {cap.rule}) is at or below "
            f'"{_NAME}".lo = {bounds.lo:g}; allowed: a lo below the ceiling'
        )
    clipped = bounds.model_copy(update={"hi": float(w)})
    params = {**settings.parameters, _NAME: clipped}
    note = (
        f'omega0 ceiling: "{_NAME}".hi clipped from {bounds.hi:g} to {w:.4g} rad/s by the '
        f"{cap.name} cap ({cap.rule})"
    )
    assert math.isfinite(w)
    return settings.model_copy(update={"parameters": params}), (note,)
