"""The AC check's positive-sequence power flow against OpenDSS's own solution of the same feeder.

For each OpenDSS feeder (IEEE 13, the IEEE 8500-node feeder, the radial ckt24) it solves:

1. OpenDSS's own solution as shipped (unbalanced; regulators move their taps, capacitors in,
   loads as defined: below ``vminpu`` a constant-power load becomes a constant impedance);
2. OpenDSS's unbalanced solution under the AC check's assumptions: loads of constant power
   (``model=1``, ``vminpu=0.5``), regulator taps held at their initial value
   (``controlmode=off``: the AC check has no taps), shunt capacitors out and transformers
   without no-load losses or magnetising current (it has no shunts);
3. the AC check (power-grid-model) of the feeder popdispatch reads from the same files: every
   load at its OpenDSS kW and kvar, the source at the Vsource's p.u., no generator output.

It prints the losses of the lines, transformers and reactors (kW, summed over OpenDSS's
power-delivery elements; the AC check's lines) and the lowest and highest bus voltage (p.u. of
each bus's base; OpenDSS: over the phases of the bus). 2 vs 3 is what a positive-sequence,
balanced model leaves out of the same network (unbalance, mostly); 1 vs 2 what the controls,
capacitors and load models do. ``docs/ac.md`` quotes its output.

Usage: ``python scripts/ac_vs_opendss.py [FEEDERS_FOLDER]`` (default ``../shared/feeders``).
"""

from __future__ import annotations

import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CKT24_OPEN = ("Line.05410_107831ug", "Line.05410_115682ug")
SOLVE = ("set maxiterations=100",)  # the 8500's run script sets 20; more do no harm
SAME_LOADS = (*SOLVE, "batchedit load..* model=1 vminpu=0.5", "set controlmode=off",
              "batchedit capacitor..* enabled=no",
              "batchedit transformer..* %noloadloss=0 %imag=0")  # fmt: skip


def opendss_solution(master: Path, commands: tuple[str, ...]) -> dict:
    """OpenDSS's own solution of ``master`` (compiled in place, its reports in a scratch
    folder: ckt24's regulator writes a trace file when it is defined)."""
    from popdispatch.readers.dss_script import compiled_script

    with compiled_script(master) as script:
        ctx = script.ctx
        for command in commands:
            ctx.Text.Command(command)
        ctx.Text.Command("solve")
        converged = ctx.Solution.Converged()
        losses, transformers = 0.0, 0.0  # W: every power-delivery element's
        more = ctx.PDElements.First()
        while more:
            watts = ctx.CktElement.Losses()[0]
            losses += watts
            transformers += watts if ctx.CktElement.Name().startswith("Transformer.") else 0.0
            more = ctx.PDElements.Next()
        losses, transformers = losses / 1e3, transformers / 1e3
        v = []
        for bus in ctx.Circuit.AllBusNames():
            ctx.Circuit.SetActiveBus(bus)
            if ctx.Bus.kVBase() > 0:
                v.extend(ctx.Bus.puVmagAngle()[0::2])
        v = np.array(v)
        v = v[v > 0.2]  # open phases, neutrals
        pu = ctx.Vsources.PU()
    return {"converged": converged, "losses_kw": losses, "transformers_kw": transformers,
            "v_min": v.min(), "v_max": v.max(), "source_pu": pu}  # fmt: skip


def ours(master: Path, source_pu: float) -> dict:
    from popdispatch.ac.check import check_setpoints, snapshot_of
    from popdispatch.feeder.generators import make_fleet
    from popdispatch.readers.opendss_direct import read_opendss_master

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        feeder = read_opendss_master(master, ratings=False)
    fleet = make_fleet([(feeder.source_bus, 0, 1, 0, 0, 1e6)], ["source"])
    feeder = feeder.with_generators(fleet)
    loads = feeder.loads.p_kw.to_numpy(float)[None, :]
    day = check_setpoints(feeder, loads, np.zeros((1, 1)), source_pu=source_pu)
    snapshot = snapshot_of(day)
    summary = snapshot.summary()
    kinds = feeder.lines["kind"].reindex(snapshot.lines.index)
    transformers = float(snapshot.lines.loss_kw[kinds.isin(["transformer", "regulator"])].sum())
    return {"losses_kw": summary["losses_kw"], "transformers_kw": transformers,
            "v_min": summary["v_min_pu"], "v_max": summary["v_max_pu"]}  # fmt: skip


def main(folder: Path) -> None:
    opendss = folder / "opendss"
    with tempfile.TemporaryDirectory() as tmp:
        ckt24 = Path(tmp) / "ckt24_radial.dss"
        ckt24.write_text(f"Compile ({opendss / 'ckt24' / 'master_ckt24.dss'})\n"
                         + "".join(f"Open {e} 1\n" for e in CKT24_OPEN))  # fmt: skip
        cases = [("IEEE 13", opendss / "ieee13" / "IEEE13Nodeckt.dss"),
                 ("IEEE 8500", opendss / "ieee8500" / "Master.dss"),
                 ("ckt24 (radial)", ckt24)]  # fmt: skip
        print(
            f"{'feeder':<16}{'model':<37}{'losses kW':>11}{'of which':>10}{'v min':>8}{'v max':>8}"
        )
        print(f"{'':<16}{'':<37}{'':>11}{'transf.':>10}")
        for label, master in cases:
            shipped = opendss_solution(master, SOLVE)
            same = opendss_solution(master, SAME_LOADS)
            mine = ours(master, same["source_pu"])
            for model, row in (("OpenDSS as shipped", shipped),
                               ("OpenDSS, the AC check's assumptions", same),
                               ("popdispatch AC check", mine)):  # fmt: skip
                note = "" if row.get("converged", True) else "  (not converged)"
                print(
                    f"{label:<16}{model:<37}{row['losses_kw']:>11.2f}"
                    f"{row['transformers_kw']:>10.2f}{row['v_min']:>8.4f}"
                    f"{row['v_max']:>8.4f}{note}"
                )


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT.parent / "shared" / "feeders")
