"""Issue #20 (the house): the Design record's ``params``, ``dims`` and ``observer`` are typed frozen records,
its ``local_models`` the T-S model's own ``LocalModel`` records, and the design document they read and write
is byte for byte what it was."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from fte_casadi.design import Design, Dims, Observer, Params
from fte_casadi.errors import DesignFileError
from fte_casadi.ts._model import LOCAL_MODEL_KEYS, LocalModel

ROOT = Path(__file__).resolve().parents[1]
COMMITTED = sorted((ROOT / "generated").glob("*/design.json"))


@pytest.fixture(scope="module", params=COMMITTED, ids=[p.parent.name for p in COMMITTED])
def committed(request):
    path = request.param
    return path, path.read_text(), Design.load(path)


def test_there_are_committed_documents():
    assert len(COMMITTED) >= 3


def test_save_of_a_loaded_document_is_the_committed_file_byte_for_byte(committed, tmp_path):
    path, text, d = committed
    d.save(tmp_path / "a.json")
    assert (tmp_path / "a.json").read_text() == text
    Design.load(tmp_path / "a.json").save(tmp_path / "b.json")
    assert (tmp_path / "b.json").read_bytes() == path.read_bytes()


def test_records_are_typed_and_agree_with_the_document(committed):
    _, text, d = committed
    doc = json.loads(text)
    assert isinstance(d.params, Params) and isinstance(d.dims, Dims) and isinstance(d.observer, Observer)
    for name in ("params", "dims", "observer"):
        rec = getattr(d, name)
        assert list(rec.keys()) == list(doc[name]), name  # the document's key order
        for k, v in doc[name].items():
            assert getattr(rec, k) == v == rec.to_dict()[k], (name, k)
    assert all(isinstance(getattr(d.dims, k), int) for k in ("n", "m", "p", "ld", "lf", "r", "nbar"))
    assert d.dims.nbar == d.nbar == d.dims.n + 2 * d.dims.lf and d.dims.r == len(d.K)
    assert d.params.gamma2 is None and "gamma2" not in d.params.to_dict()
    assert d.observer.alpha > 0 and d.observer.sample_time > 0 and d.checks["ts_max"] > d.observer.sample_time


def test_records_are_frozen(committed):
    d = committed[2]
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.dims.n = 3
    with pytest.raises(TypeError):
        d.params["sigma"] = 1.0  # no item assignment either
    with pytest.raises(TypeError):
        d.params["sigma"]  # the records are not mappings: read attributes
    with pytest.raises(AttributeError):
        d.observer.get("alpha")


def test_an_older_document_without_the_newer_keys_loads_and_saves_as_it_was(committed, tmp_path):
    doc = json.loads(committed[1])
    for k in ("observer", "x0", "params_chosen", "bounds", "solves", "certified", "status"):
        doc.pop(k, None)
    d = Design.from_dict(doc)
    assert d.observer.to_dict() == {} and d.observer.keys() == () and d.observer.alpha is None
    out = d.to_dict()
    assert out["observer"] == {} and out["params"] == doc["params"] and out["dims"] == doc["dims"]


def test_keys_a_record_does_not_type_survive_a_round_trip(committed):
    doc = json.loads(committed[1])
    params = {k: v for k, v in doc["params"].items() if k != "kappa"}  # the tuned three-tank's has one
    doc["params"] = {"kappa": 500.0, **params, "later_knob": 2.5}
    doc["observer"] = {**doc["observer"], "sample_time": None, "later_note": "x"}
    d = Design.from_dict(doc)
    assert (
        d.params.kappa == 500.0
        and d.params.extra["later_knob"] == 2.5
        and d.params.extra == {"later_knob": 2.5}
    )
    assert (
        d.observer.sample_time is None and "sample_time" in d.observer.keys()
    )  # held as null, written as null
    assert d.observer.extra["later_note"] == "x"
    again = json.loads(d.to_json())
    for name in ("params", "dims", "observer"):
        assert list(again[name].items()) == list(doc[name].items()), name


def test_a_document_lacking_a_required_size_or_parameter_is_refused_by_name(committed):
    for entry, key in (("dims", "nbar"), ("params", "sigma")):
        doc = json.loads(committed[1])
        del doc[entry][key]
        with pytest.raises(DesignFileError, match=rf"'{entry}' lacks \['{key}'\]"):
            Design.from_dict(doc)
    doc = json.loads(committed[1])
    doc["observer"] = [1, 2]
    with pytest.raises(DesignFileError, match="'observer' must be a JSON object"):
        Design.from_dict(doc)


def test_dicts_given_for_the_records_become_records(committed):
    d = committed[2]
    e = dataclasses.replace(d, observer={k: v for k, v in d.observer.to_dict().items() if k != "sample_time"},
                            params=dict(d.params.to_dict(), sigma=2 * d.params.sigma))  # fmt: skip
    assert (
        isinstance(e.observer, Observer)
        and e.observer.sample_time is None
        and "sample_time" not in e.observer.keys()
    )
    assert isinstance(e.params, Params) and e.params.sigma == 2 * d.params.sigma
    assert e.params.keys() == d.params.keys()  # the order of the dict given


def test_replace_keeps_the_order_and_appends_a_new_key(committed):
    # without the boundary layer the tuned three-tank's design has
    p = Params.from_mapping({k: v for k, v in committed[2].params.to_dict().items() if k != "boundary_layer"})
    q = p.replace(boundary_layer=0.25, sigma=p.sigma / 2)
    assert q.boundary_layer == 0.25 and q.sigma == p.sigma / 2 and p.boundary_layer is None
    assert list(q.to_dict()) == list(p.to_dict()) + ["boundary_layer"]
    assert q != p and p.replace() == p and p != p.to_dict()  # a record equals records only


# -- the local models: the T-S model's own records, one type for both (issue #20, "the local models once") --
def test_local_models_are_the_typed_records_and_agree_with_the_document(committed):
    _, text, d = committed
    doc = json.loads(text)
    assert len(d.local_models) == d.r == len(doc["local_models"])
    for lm, entry in zip(d.local_models, doc["local_models"]):
        assert isinstance(lm, LocalModel)
        assert list(lm.to_dict()) == list(entry) == list(LOCAL_MODEL_KEYS)  # the document's key order
        for k, v in entry.items():
            assert getattr(lm, k).dtype == float and getattr(lm, k).tolist() == v, k
            assert lm[k] is getattr(lm, k)  # the transitional item access reads the same array
        assert lm.A.shape == (d.dims.n, d.dims.n) and lm.B.shape == (d.dims.n, d.dims.m)


def test_a_design_holds_the_very_records_of_its_ts_model(ts_models, real_designs):
    ts, d = ts_models["manipulator"], real_designs["manipulator"]
    assert d.local_models == ts.local_models  # the same records, not copies converted to dicts
    assert all(a is b for a, b in zip(d.local_models, ts.local_models))
    assert d.to_dict()["local_models"] == ts.to_dict()["local_models"]  # design and derive documents agree


def test_an_older_local_model_without_the_optional_matrices_loads_and_saves_as_it_was(committed):
    doc = json.loads(committed[1])
    n, m, lf = doc["dims"]["n"], doc["dims"]["m"], doc["dims"]["lf"]
    for entry in doc["local_models"]:
        for k in ("a", "G", "Gf", "M"):
            del entry[k]
    d = Design.from_dict(doc)
    lm = d.local_models[0]
    assert lm.a.shape == (n,) and lm.G.shape == (n, m) and lm.Gf.shape == (n, lf) and lm.M.shape == (n, 0)
    assert not lm.has_diffusion_extension and not np.any(d.affine(0))
    out = d.to_dict()["local_models"]
    # written back with the keys it had, plus the affine offset "a" (zeros) that documents always carry
    assert [list(e) for e in out] == [["A", "B", "Bd", "Bf", "W", "a"]] * d.r
    assert out[0]["a"] == [0.0] * n and out[0]["A"] == doc["local_models"][0]["A"]


def test_an_unknown_local_model_key_survives_a_round_trip(committed):
    doc = json.loads(committed[1])
    doc["local_models"][0] = {"later": [[1.5]], **doc["local_models"][0]}
    d = Design.from_dict(doc)
    assert d.local_models[0].extra["later"].tolist() == [[1.5]] and d.local_models[0]["later"][0, 0] == 1.5
    again = json.loads(d.to_json())
    assert again["local_models"] == doc["local_models"]
    assert list(again["local_models"][0]) == list(doc["local_models"][0])


def test_a_malformed_local_model_is_refused_by_name(committed):
    doc = json.loads(committed[1])
    del doc["local_models"][1]["Bf"]
    with pytest.raises(DesignFileError, match=r"'local_models\[1\]' lacks the matrix 'Bf'"):
        Design.from_dict(doc)
    doc = json.loads(committed[1])
    doc["local_models"][0] = [[1.0]]
    with pytest.raises(DesignFileError, match=r"'local_models\[0\]' must be a JSON object"):
        Design.from_dict(doc)
    doc = json.loads(committed[1])
    doc["local_models"][0]["A"][0][0] = None
    with pytest.raises(DesignFileError, match=r"'local_models\[0\].A' holds a NaN"):
        Design.from_dict(doc)


def test_dicts_given_for_the_local_models_become_records(committed):
    d = committed[2]
    e = dataclasses.replace(d, local_models=[lm.to_dict() for lm in d.local_models])
    assert isinstance(e.local_models, tuple) and all(isinstance(lm, LocalModel) for lm in e.local_models)
    assert e.to_json() == d.to_json()


def test_a_document_before_0_2_0_is_read_with_each_value_once(committed):
    """Before 0.2.0 the observer entry also held ``ts_max`` and ``bound_weight`` (copies of ``checks.ts_max``
    and ``params.bound_weight``) and named ``bound_objective_unweighted`` ``bound_objective_before``."""
    doc = json.loads(committed[1])
    obs = doc["observer"]
    old = {"sample_time": obs.get("sample_time"), "alpha": obs.get("alpha"), "why": obs.get("why"),
           "ts_max": doc["checks"]["ts_max"], "bound_weight": 0.5, "bound_objective_before": 5.0,
           "bound_objective": 2.0}  # fmt: skip
    doc["observer"] = old
    d = Design.from_dict(doc)
    assert d.observer.bound_objective_unweighted == 5.0 and d.observer.bound_objective == 2.0
    saved = json.loads(d.to_json())["observer"]
    assert list(saved) == ["sample_time", "alpha", "why", "bound_objective_unweighted", "bound_objective"]
    assert saved["bound_objective_unweighted"] == 5.0
    assert not hasattr(d.observer, "ts_max") and d.checks["ts_max"] == old["ts_max"]


# -- one policy for non-finite numbers: null with the reason, or a refusal; never a finite stand-in --------
def _numbers(obj):
    if isinstance(obj, dict):
        return [x for v in obj.values() for x in _numbers(v)]
    if isinstance(obj, list):
        return [x for v in obj for x in _numbers(v)]
    return [obj] if isinstance(obj, (int, float)) and not isinstance(obj, bool) else []


def test_a_nan_check_is_written_as_null_with_its_reason_and_read_back_as_nan(committed, tmp_path):
    from fte_casadi.design.core._certify import failures

    d = committed[2]
    checks = json.loads(json.dumps(d.checks))
    checks["lmi_max_eig"]["45"] = float("nan")
    if "lmi_balanced_max_eig" in checks:
        checks["lmi_balanced_max_eig"]["45"] = float("nan")  # neither form evaluated
    checks["lmi_max_eig"]["46"] = float("-inf")
    checks["cond_Pbar"] = np.float64("inf")
    bad = dataclasses.replace(d, checks=checks, certified=False)
    bad.save(tmp_path / "nan.json")
    text = (tmp_path / "nan.json").read_text()
    doc = json.loads(text)
    assert doc["checks"]["lmi_max_eig"]["45"] is None and doc["checks"]["lmi_max_eig"]["46"] is None
    assert doc["checks"]["cond_Pbar"] is None
    assert doc["nonfinite"]["checks.lmi_max_eig.45"].startswith("NaN: ")
    assert doc["nonfinite"]["checks.lmi_max_eig.46"].startswith("-inf: ")
    assert doc["nonfinite"]["checks.cond_Pbar"].startswith("+inf: ")
    # no finite stand-in anywhere: the largest magnitude written is that of the design's own numbers
    assert "e+308" not in text and "e308" not in text
    assert max(abs(x) for x in _numbers(doc["checks"])) < 1e300
    back = Design.load(tmp_path / "nan.json")
    assert np.isnan(back.checks["lmi_max_eig"]["45"]) and back.checks["lmi_max_eig"]["46"] == -np.inf
    assert back.checks["cond_Pbar"] == np.inf
    assert any(s.startswith("LMI (45)") for s in failures(back.checks))  # a NaN is no certificate
    back.save(tmp_path / "again.json")
    assert (tmp_path / "again.json").read_text() == text  # a round trip keeps the nulls and their reasons


def test_open_input_limits_are_null_with_their_reason(committed, tmp_path):
    d = committed[2]
    m = d.dims.m
    lim = np.tile([-np.inf, 2.0], (m, 1))
    lim[0, 1] = np.inf
    e = dataclasses.replace(d, input_limits=lim)
    doc = json.loads(e.to_json())
    assert doc["input_limits"][0] == [None, None] and doc["input_limits"][-1][1] in (2.0, None)
    assert doc["nonfinite"]["input_limits.0.0"] == "-inf: no limit on this side"
    assert doc["nonfinite"]["input_limits.0.1"] == "+inf: no limit on this side"
    e.save(tmp_path / "lim.json")
    np.testing.assert_array_equal(Design.load(tmp_path / "lim.json").input_limits, lim)


def test_a_non_finite_matrix_is_refused_by_name(committed, tmp_path):
    d = committed[2]
    Pbar = np.array(d.Pbar, dtype=float)
    Pbar[0, 0] = np.nan
    with pytest.raises(DesignFileError, match="'Pbar"):
        dataclasses.replace(d, Pbar=Pbar).save(tmp_path / "bad.json")
    assert not (tmp_path / "bad.json").exists()
