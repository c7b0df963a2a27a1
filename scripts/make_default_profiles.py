"""Generate the shipped offline default load profiles (popdispatch/data/default_profiles.csv.gz).

The IEEE European LV Test Feeder's official profiles were made with the CREST demand model
(Richardson et al.). ``richardsonpy`` is a Python implementation of that model, but it is
GPL-licensed, so popdispatch does not depend on it at run time: this script runs it once, with a
fixed seed, and the package ships only the resulting numbers.

What is simulated: 55 households (one per feeder load ``LOAD1``..``LOAD55``), one winter weekday
(day-of-year :data:`DAY_OF_YEAR`, a Monday, irradiance of richardsonpy's bundled German test
reference year), 1-minute resolution. Household sizes (1..5 occupants) are drawn from
:data:`HOUSEHOLD_SIZE_SHARES`. Per household the script builds a CREST occupancy profile, a
random appliance set (no electric space or water heating) and one of the 100 bundled lighting
configurations and runs one day of appliance and lighting
use.

Scaling: the raw simulation peaks at about 79 kW aggregate, above the 65 kW total capacity of the
paper's fleet, so a day on it would be infeasible. All 55 profiles are therefore multiplied by one
common factor (:func:`scale_to_peak`) so that the aggregate daily peak equals
:data:`TARGET_PEAK_KW` = 57.358 kW, the aggregate peak of the official IEEE feeder profiles
(minute 566). The factor is found by bisection so that the peak is exactly 57.358 kW *after*
rounding to 1 W; it is recorded in the file header. Apart from the 1 W rounding the shape of
every profile is kept, and the default still peaks at its own minute (1161, an evening peak).
Power is written in kW rounded to 3 decimals (1 W).

Usage (needs ``pip install richardsonpy``; runs offline, richardsonpy ships its input data)::

    python scripts/make_default_profiles.py            # writes the shipped file
    python scripts/make_default_profiles.py --check    # regenerate and compare, exit 1 if different

The output is byte-for-byte reproducible for a given richardsonpy version and seed.
"""

from __future__ import annotations

import argparse
import gzip
import io
import random
import sys
from pathlib import Path

import numpy as np

SEED = 20240566
N_LOADS = 55
DAY_OF_YEAR = 14  # 0-based day index of the computation year: 15 January
INITIAL_WEEKDAY = 1  # Monday
#: Share of households with 1, 2, 3, 4, 5 occupants (roughly the UK census of the CREST data).
HOUSEHOLD_SIZE_SHARES = (0.29, 0.35, 0.16, 0.14, 0.06)
#: Aggregate daily peak (kW) of the shipped profiles: that of the official IEEE feeder profiles.
TARGET_PEAK_KW = 57.358
OUTPUT = (
    Path(__file__).resolve().parents[1] / "src" / "popdispatch" / "data" / "default_profiles.csv.gz"
)


def simulate(seed: int = SEED) -> tuple[np.ndarray, list[int]]:
    """Simulate the households; returns ``(kw, occupants)``, ``kw`` of shape (1440, 55) in kW."""
    import richardsonpy
    import richardsonpy.classes.appliance as app_model
    import richardsonpy.classes.lighting as light_model
    import richardsonpy.classes.occupancy as occ_model
    import richardsonpy.classes.stochastic_el_load_wrapper as wrapper
    import richardsonpy.functions.load_radiation as loadrad
    from richardsonpy.classes.electric_load import ElectricLoad

    random.seed(seed)  # richardsonpy draws all its random numbers from the stdlib ``random``
    rng = np.random.default_rng(seed)
    occupants = [int(n) for n in rng.choice(np.arange(1, 6), N_LOADS, p=HOUSEHOLD_SIZE_SHARES)]

    inputs = Path(richardsonpy.__file__).resolve().parent / "inputs"
    lighting_configs = rng.integers(0, 100, N_LOADS)  # LightBulbs.csv has 100 house configurations
    q_direct, q_diffuse = loadrad.get_rad_from_try_path()  # W/m2, hourly, one year
    hourly = (q_direct + q_diffuse)[24 * DAY_OF_YEAR : 24 * (DAY_OF_YEAR + 1)]
    irradiance = np.interp(np.arange(1440), 60 * np.arange(24), hourly)  # per minute

    kw = np.zeros((1440, N_LOADS))
    for j, n in enumerate(occupants):
        occupancy = occ_model.Occupancy(number_occupants=n, initial_day=INITIAL_WEEKDAY, nb_days=1)
        appliances = app_model.Appliances(
            str(inputs / "Appliances.csv"),
            annual_consumption=0.91 * ElectricLoad.standard_consumption["SFH"][n],
            randomize_appliances=True,
            prev_heat_dev=True,  # no electric space or water heating (a gas-heated UK street)
        )
        lights = light_model.load_lighting_profile(
            filename=str(inputs / "LightBulbs.csv"), index=int(lighting_configs[j])
        )
        profile = wrapper.ElectricityProfile(appliances, lights)
        total_w, _, _ = profile.power_sim(
            irradiation=irradiance,
            weekend=INITIAL_WEEKDAY >= 6,
            day=DAY_OF_YEAR,
            occupancy=occupancy.occupancy[:144],
        )
        kw[:, j] = np.asarray(total_w, dtype=float)[:1440] / 1000.0
    return kw, occupants


def scale_to_peak(kw: np.ndarray, peak_kw: float = TARGET_PEAK_KW) -> tuple[np.ndarray, float]:
    """Scale all profiles by one common factor so the rounded (1 W) aggregate peak is ``peak_kw``.

    Returns ``(scaled_kw, factor)``; ``scaled_kw`` is already rounded to 3 decimals of kW. The
    rounded aggregate peak is a non-decreasing step function of the factor, so the smallest factor
    reaching ``peak_kw`` is found by bisection (deterministic floating-point arithmetic).
    """
    watts = np.asarray(kw, dtype=float) * 1000.0
    target = round(peak_kw * 1000.0)

    def peak(factor: float) -> int:
        return int(np.rint(watts * factor).sum(axis=1).max())

    guess = peak_kw / float(kw.sum(axis=1).max())
    lo, hi = 0.99 * guess, 1.01 * guess
    if not peak(lo) < target <= peak(hi):
        raise RuntimeError(f"cannot bracket the scale factor for a {peak_kw} kW peak")
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        if peak(mid) < target:
            lo = mid
        else:
            hi = mid
    if peak(hi) != target:
        raise RuntimeError(f"no common factor gives a {peak_kw} kW peak at 1 W resolution")
    return np.rint(watts * hi) / 1000.0, hi


def to_csv_gz(kw: np.ndarray, occupants: list[int], seed: int, factor: float) -> bytes:
    """Encode the profiles as a reproducible gzip CSV (minute, LOAD1..LOAD55; kW, 3 decimals)."""
    import richardsonpy

    version = getattr(richardsonpy, "__version__", None)
    if version is None:
        from importlib.metadata import version as dist_version

        version = dist_version("richardsonpy")
    text = io.StringIO()
    text.write(
        f"# synthetic default (richardsonpy CREST, seed {seed}, "
        f"scaled to a {TARGET_PEAK_KW:.3f} kW peak)\n"
    )
    text.write(
        f"# richardsonpy {version}; day index {DAY_OF_YEAR} (weekday {INITIAL_WEEKDAY}); "
        f"all loads scaled by {factor!r}; "
        "kW per load per minute; generated by scripts/make_default_profiles.py\n"
    )
    text.write("# occupants: " + " ".join(str(n) for n in occupants) + "\n")
    text.write("minute," + ",".join(f"LOAD{j + 1}" for j in range(kw.shape[1])) + "\n")
    rounded = np.round(kw, 3)
    for minute, row in enumerate(rounded, start=1):
        text.write(f"{minute}," + ",".join(f"{v:.3f}" for v in row) + "\n")
    buffer = io.BytesIO()
    with gzip.GzipFile(filename="", mode="wb", fileobj=buffer, mtime=0, compresslevel=9) as gz:
        gz.write(text.getvalue().encode("ascii"))
    return buffer.getvalue()


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit code."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=SEED)
    parser.add_argument("--output", type=Path, default=OUTPUT)
    parser.add_argument("--check", action="store_true", help="compare with the existing file")
    args = parser.parse_args(argv)
    raw, occupants = simulate(args.seed)
    kw, factor = scale_to_peak(raw)
    data = to_csv_gz(kw, occupants, args.seed, factor)
    total = kw.sum(axis=1)
    print(
        f"55 households, occupants {np.bincount(occupants, minlength=6)[1:].tolist()} (1..5); "
        f"raw peak {raw.sum(axis=1).max():.3f} kW, scaled by {factor:.6f}: "
        f"aggregate peak {total.max():.3f} kW at minute {int(total.argmax()) + 1}, "
        f"energy {total.sum() / 60:.1f} kWh/day; {len(data)} bytes"
    )
    if args.check:
        same = args.output.exists() and args.output.read_bytes() == data
        print("identical" if same else f"DIFFERENT from {args.output}")
        return 0 if same else 1
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_bytes(data)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
