"""OpenDSS run scripts compiled in place as OpenDSS reads them (popdispatch.readers.dss_script):
Windows file names, ``Compile (...)``, edits after the compile, commands that solve, show, plot
or export skipped without side effects, errors naming file and line.

The yardstick is OpenDSS itself: the same circuit written with exact, Linux-spelled file names
and compiled natively by a separate OpenDSSDirect.py context.
"""

from __future__ import annotations

import warnings

import pytest

from popdispatch.errors import FeederError, MeshedError

opendssdirect = pytest.importorskip("opendssdirect", reason="needs popdispatch[opendss]")

from popdispatch.readers.dss_script import (  # noqa: E402
    compiled_script,
    first_argument,
    strip_comment,
)
from popdispatch.readers.opendss_direct import read_opendss_master  # noqa: E402

MASTER = """Clear
New Circuit.tiny basekV=12.47 pu=1.0 bus1=src
/* a block comment
Show voltages
*/
Redirect SUB\\LineCodes.DSS   ! Windows separator and spelling
redir sub\\lines.dss
New Loadshape.day npts=4 interval=6 mult=(file=Shapes\\DAY.TXT)
New Load.a bus1=b kV=12.47 kW=100 kvar=30 daily=day
New Load.c bus1=c kV=12.47 kW=50 kvar=10
Set voltagebases=[12.47]
Calcvoltagebases
"""
LINECODES = "New Linecode.lc nphases=3 r1=0.3 x1=0.6 r0=0.9 x0=1.8 units=km\n"
LINES = """New Line.ab bus1=src bus2=b linecode=lc length=1 units=km
New Line.bc bus1=b bus2=c linecode=lc length=2 units=km
New Line.bd bus1=b bus2=d linecode=lc length=1 units=km switch=y
"""
RUN = """! as shipped: the master's name in another case, in parentheses
Compile (master.dss)
Edit Load.a kW=120
Load.c.kW=60
New Load.e bus1=c kV=12.47 kW=5
Open Line.bd 1
Set demand=true casename=study
Set mode=daily
Solve
Show voltages LN Nodes
Export powers
Plot circuit Power max=500
CloseDI
Summary
"""


def write_case(folder):
    """The tiny circuit as a Windows user has it (files named in other cases than on disk)."""
    (folder / "sub").mkdir()
    (folder / "Shapes").mkdir()
    (folder / "Master.dss").write_text(MASTER)
    (folder / "sub" / "linecodes.dss").write_text(LINECODES)
    (folder / "sub" / "Lines.dss").write_text(LINES)
    (folder / "Shapes" / "day.txt").write_text("0.5\n1.0\n0.8\n0.3\n")
    (folder / "Run.dss").write_text(RUN)
    return folder / "Run.dss"


def native_totals(folder, extra: str = "") -> dict:
    """OpenDSS's own compile of the same circuit with exact file names (written beside it)."""
    exact = (
        MASTER.replace("SUB\\LineCodes.DSS", "sub/linecodes.dss")
        .replace("redir sub\\lines.dss", "redir sub/Lines.dss")
        .replace("Shapes\\DAY.TXT", "Shapes/day.txt")
    )
    (folder / "exact.dss").write_text(exact + extra)
    ctx = opendssdirect.NewContext()
    ctx.Basic.AllowChangeDir(False)
    ctx.Text.Command(f'compile "{folder / "exact.dss"}"')
    loads = {}
    for name in ctx.Loads.AllNames():
        ctx.Loads.Name(name)
        loads[name] = ctx.Loads.kW()
    ctx.LoadShape.Name("day")
    return {"loads": loads, "day": list(ctx.LoadShape.PMult())[:4]}


def test_run_script_reads_as_opendss_reads_it(tmp_path):
    run = write_case(tmp_path)
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        feeder = read_opendss_master(run)
    assert [str(w.message).split(": ", 1)[1] for w in caught] == [
        "dropped 1 bus(es) cut off from the source, with nothing connected: ['d']"
    ]  # no file missing; the skipped commands change nothing read
    with compiled_script(run) as script:  # what was not run, all of it output only
        assert dict(script.skipped) == {
            "solve": 1, "show": 1, "export": 1, "plot": 1, "closedi": 1, "summary": 1}  # fmt: skip
    # nothing written beside the files (demand intervals, case folder, exports, reports)
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before
    own = native_totals(tmp_path, "Edit Load.a kW=120\nLoad.c.kW=60\n"
                                  "New Load.e bus1=c kV=12.47 kW=5\n")  # fmt: skip
    assert feeder.loads.p_kw.to_dict() == pytest.approx(own["loads"])
    assert own["loads"] == pytest.approx({"a": 120.0, "c": 60.0, "e": 5.0})
    # the open switch removed its line; its far bus (nothing on it) is dropped
    assert "bd" not in feeder.lines.index and "d" not in set(feeder.buses.name)
    # the load shape's file was found under its Windows spelling
    assert list(feeder.shapes["day"].mult) == pytest.approx(own["day"]) == [0.5, 1.0, 0.8, 0.3]
    assert feeder.loads.loc["a", "daily"] == "day"


def test_master_alone_and_the_run_script_give_the_same_circuit(tmp_path):
    run = write_case(tmp_path)
    scripted = read_opendss_master(run)
    master = read_opendss_master(tmp_path / "Master.dss")
    assert master.lines.index.tolist() == ["ab", "bc", "bd"]
    assert scripted.lines.index.tolist() == ["ab", "bc"]
    for column in ("r_ohm", "x_ohm", "limit_kw"):
        assert scripted.lines[column].tolist() == master.lines.loc[["ab", "bc"], column].tolist()


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        ("New Line.zz bus1=c bus2=z linecode=nowhere", ["Run.dss:15", "LineCode", "nowhere"]),
        ("New Line.zz bus1=c bus2=z flavour=3", ["Run.dss:15", "flavour", "Line.zz"]),
        ("Frobnicate all", ["Run.dss:15", "Unknown Command", "Frobnicate"]),
    ],
)
def test_a_statement_opendss_refuses_names_file_line_and_element(tmp_path, extra, words):
    run = write_case(tmp_path)
    run.write_text(RUN + extra + "\n")
    with pytest.raises(FeederError) as exc:
        read_opendss_master(run)
    message = str(exc.value)
    assert "\n" not in message
    for word in words:
        assert word in message, message


def test_unsupported_series_element_names_its_file_and_line(tmp_path):
    run = write_case(tmp_path)
    run.write_text(RUN + "New Fault.f1 bus1=b bus2=c r=0.1\n")
    with pytest.raises(FeederError, match=r"Run.dss:15: Fault.f1: unsupported series element"):
        read_opendss_master(run)


def test_missing_redirect_is_skipped_with_a_note_as_opendss_does(tmp_path):
    run = write_case(tmp_path)
    run.write_text(RUN + "Redirect monitors.dss\n")
    with pytest.warns(UserWarning, match=r"Run.dss:15: redirect of a missing file "
                      r"'monitors.dss' skipped \(OpenDSS error 243\)"):  # fmt: skip
        read_opendss_master(run)


def test_a_loop_names_the_least_loaded_element_of_opendss_own_solution(tmp_path):
    run = write_case(tmp_path)
    run.write_text(RUN + "Close Line.bd 1\nNew Line.dc bus1=d bus2=c linecode=lc length=5\n")
    with pytest.raises(MeshedError) as exc:
        read_opendss_master(run)
    message = str(exc.value)
    assert "feeder is meshed" in message and "\n" not in message
    assert "open it in a run script after the Compile (`Open Line." in message
    assert set(exc.value.loop_lines) == {"dc", "bc", "bd"}


def test_comment_and_argument_parsing():
    assert strip_comment('New Line.x bus1=a ! note "quoted"') == "New Line.x bus1=a"
    assert strip_comment("mult=(file=a!b.txt) // c") == "mult=(file=a!b.txt)"
    assert strip_comment('x="a//b"') == 'x="a//b"'
    assert first_argument("Compile (master.dss)") == "master.dss"
    assert first_argument('redirect "my file.dss" extra') == "my file.dss"
    assert first_argument("Compile file=Master.dss") == "Master.dss"
    assert first_argument("buscoords coords.csv") == "coords.csv"


CENTRE_TAP = """Clear
New Circuit.ct basekv=12.47 pu=1.0 phases=3 bus1=src MVAsc3=1e9 MVAsc1=1e9
New XfmrCode.CT25 phases=1 windings=3 kvs=[7.2 0.12 0.12] kVAs=[25 25 25] %imag=0
~ %Rs=[0.6 1.2 1.2] %noloadloss=0 Xhl=2.04 Xht=2.04 Xlt=1.36
New Transformer.t XfmrCode=CT25 buses=[src.1 sec.1.0 sec.0.2]
{loads}
Set voltagebases=[12.47 0.208]
Calcvoltagebases
"""


@pytest.mark.parametrize(
    "loads",
    [
        "New Load.a bus1=sec.1.0 phases=1 kV=0.12 kW=10 pf=1 model=1\n"
        "New Load.b bus1=sec.2.0 phases=1 kV=0.12 kW=10 pf=1 model=1",
        "New Load.c bus1=sec.1.2 phases=1 kV=0.24 kW=20 pf=1 model=1",
    ],
    ids=["two-halves", "240V"],
)
def test_split_phase_transformer_loses_what_opendss_says(tmp_path, loads):
    """The centre-tap unit's one branch (z1 + z2 z3 / (z2 + z3) on its primary) carries the
    current OpenDSS's own solution gives it with the losses OpenDSS computes, within 0.1 %."""
    path = tmp_path / "ct.dss"
    path.write_text(CENTRE_TAP.format(loads=loads))
    branch = read_opendss_master(path).lines.loc["Transformer.t"]
    assert branch.kv_base == pytest.approx(12.47, rel=1e-3) and branch.limit_kw == 25.0
    ctx = opendssdirect.NewContext()
    ctx.Basic.AllowChangeDir(False)
    ctx.Text.Command(f'compile "{path}"')
    ctx.Text.Command("solve")
    ctx.Circuit.SetActiveElement("Transformer.t")
    loss_kw = ctx.CktElement.Losses()[0] / 1e3
    current_a = ctx.CktElement.CurrentsMagAng()[0]  # primary, A
    assert current_a**2 * branch.r_ohm / 1e3 == pytest.approx(loss_kw, rel=1e-3)


@pytest.mark.parametrize(
    "extra",
    [
        "New SwtControl.s1 SwitchedObj=Line.bd SwitchedTerm=1 Normal=open State=open",
        "New Fuse.f1 MonitoredObj=Line.bd SwitchedObj=Line.bd\nFuse.f1.State=[open open open]",
        "Disable Line.bd",
        "Edit Line.bd enabled=no",
    ],
    ids=["switch-control", "blown-fuse", "disable", "enabled-no"],
)
def test_controls_and_disabled_elements_take_a_line_out(tmp_path, extra):
    write_case(tmp_path)
    master = tmp_path / "Master.dss"
    master.write_text(MASTER + extra + "\n")
    with warnings.catch_warnings():  # an opened line's far bus is dropped with a note
        warnings.simplefilter("ignore", UserWarning)
        feeder = read_opendss_master(master)
    assert "bd" not in feeder.lines.index and "d" not in set(feeder.buses.name)
    plain = tmp_path / "plain.dss"
    plain.write_text(MASTER)
    assert "bd" in read_opendss_master(plain).lines.index
