"""Study files: the ``[drive]`` table of ``type = "harmonic"`` (registered in `gearte._config.DRIVES`).

    [drive]
    type = "harmonic"
    z_flexspline = 180            # z₁
    z_circular_spline = 182       # z₂
    pitch_diameter_mm = 90        # d, FS pitch diameter
    pressure_angle_deg = 20       # α_n (or pressure_angle_rad)
    K_b = 1.0                     # optional, default 1.0
    teeth_in_mesh = 36.2          # optional, default 0.1 (z₁ + z₂)
    waves = 2                     # optional; only 2 is supported

    [[drive.sources]]             # one table per error source
    name = "cs_pitch"
    class = "circular_spline"     # circular_spline | flexspline | wave_generator | tooth
    kind = "cumulative_pitch"     # runout (default) | cumulative_pitch | tooth_to_tooth
    tolerance_um = 25

    [drive.record]                # optional: the encoder record and spectrum of `gearte run`
    input_rpm = 184
    duration_s = 80
    sample_rate_hz = 4000
    lines = 8                     # list at least this many spectral peaks

    [drive.assembly]              # optional: assembly phases to optimise on the typical unit
    adjustable = ["cs_bore_runout"]
    starts = 32

Each source then needs its ``[errors.NAME]`` table (magnitude law and phase rule);
its ``tolerance_um`` there may be left out (the drive's is used) or must agree.
"""

from __future__ import annotations

import math

from .harmonic import CLASSES, KINDS, HarmonicDrive, HarmonicRunSettings, HarmonicSource


def build(t) -> HarmonicDrive:
    """Build a `HarmonicDrive` from the ``[drive]`` table `t` (a `gearte._config._Table`)."""
    from .._config import ConfigError, _Table

    z1 = t.integer("z_flexspline", minimum=1)
    z2 = t.integer("z_circular_spline", minimum=1)
    waves = t.integer("waves", 2, minimum=1)
    d = t.number("pitch_diameter_mm", positive=True)
    alpha = t.angle("pressure_angle", math.radians(20.0))
    kb = t.number("K_b", 1.0, positive=True)
    n_mesh = t.number("teeth_in_mesh", positive=True) if t.has("teeth_in_mesh") else None
    raw = t.get("sources")
    if not isinstance(raw, list) or not raw:
        raise ConfigError(f"{t.where} sources: give the error sources as [[drive.sources]] tables "
                          "(name, class, kind, tolerance_um)")
    sources = []
    for i, item in enumerate(raw):
        st = _Table(item, f"[[drive.sources]] #{i + 1}")
        name = st.string("name")
        st.where = f"[[drive.sources]] #{i + 1} ({name})"
        cls = st.string("class", choices=tuple(CLASSES))
        kind = st.string("kind", CLASSES[cls]["kinds"][0], choices=KINDS)
        tol = st.number("tolerance_um", minimum=0)
        st.finish()
        try:
            sources.append(HarmonicSource(name, cls, kind=kind, tolerance=tol))
        except ValueError as e:
            raise ConfigError(f"{st.where}: {e}") from None
    settings = None
    rec = t.table("record", None)
    asm = t.table("assembly", None)
    if asm is not None and rec is None:
        raise ConfigError(f"{t.where}: [drive.assembly] needs a [drive.record] table too (the record shows the assembled unit)")
    if rec is not None:
        adjustable, starts = (), 32
        if asm is not None:
            adj = asm.get("adjustable")
            if not isinstance(adj, list) or not all(isinstance(x, str) for x in adj) or not adj:
                raise ConfigError(f"{asm.where} adjustable: expected a list of source names, e.g. [\"cs_bore_runout\"]")
            adjustable = tuple(adj)
            starts = asm.integer("starts", 32, minimum=1)
            asm.finish()
        try:
            settings = HarmonicRunSettings(input_rpm=rec.number("input_rpm", positive=True),
                                           duration_s=rec.number("duration_s", positive=True),
                                           sample_rate_hz=rec.number("sample_rate_hz", positive=True),
                                           lines=rec.integer("lines", 8, minimum=1), adjustable=adjustable,
                                           assembly_starts=starts)
        except ValueError as e:
            raise ConfigError(f"{rec.where}: {e}") from None
        rec.finish()
    try:
        return HarmonicDrive(z1, z2, sources, pitch_diameter=d, pressure_angle=alpha, k_b=kb, teeth_in_mesh=n_mesh,
                             waves=waves, run_settings=settings)
    except ValueError as e:
        raise ConfigError(f"{t.where}: {e}") from None
