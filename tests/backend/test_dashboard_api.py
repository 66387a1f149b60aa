"""What the dashboard needs from the REST API, with the fast stand-in loop (conftest.FakeLoop): a running
run's history with numbered events that the stream continues without gaps or repeats; a start that a
double click cannot duplicate; labels and deletion in the runs list; CSV and report exports; plain
refusals; the glossary of the help tooltips."""

from __future__ import annotations

import concurrent.futures
import csv
import io
import time
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.settings import Settings
from conftest import FakeFactory, fake_factory, stream_frames, wait_status
from twin.runs.metrics import METRIC_KEYS

RUN = {"duration": 6.0, "speed": 4.0, "reference": {"setpoint": 900.0, "t_E": 3.0}}


def make_client(tmp_path: Path, cfg, factory=None) -> TestClient:
    return TestClient(create_app(Settings(data_dir=tmp_path / "data"), cfg, loop_factory=factory or fake_factory()),
                      base_url="http://127.0.0.1")


class SlowCheckFactory(FakeFactory):
    """A factory whose reference check takes a while: two starts overlap inside it."""

    def check_reference(self, cfg, ref) -> None:
        time.sleep(0.4)
        super().check_reference(cfg, ref)


def test_history_and_stream_give_every_event_once(tmp_path, small_cfg) -> None:
    with make_client(tmp_path, small_cfg) as c:
        run_id = c.post("/api/runs", json=RUN).json()["id"]
        mid: dict = {}

        def on_frame(f: dict) -> None:
            if "series" not in mid and f["t"] >= 2.0:  # a page that connects mid-run reads the history
                mid["series"] = c.get(f"/api/runs/{run_id}/series").json()
                mid["t"] = f["t"]
            if "change" not in mid and f["t"] >= 3.0:
                mid["change"] = c.put(f"/api/runs/{run_id}/reference", json={"setpoint": 950.0, "t_E": 1.5})

        frames = stream_frames(c, run_id, on_frame)
        detail = wait_status(c, run_id, {"finished"})
        final = c.get(f"/api/runs/{run_id}/series").json()
    hist = mid["series"]
    # the history starts at the run's first sample and reaches (at least) the frame that was on screen
    assert hist["t"][0] == pytest.approx(0.1) and hist["t"][-1] >= mid["t"] - 1e-9
    # the events: numbered 0, 1, 2, ... ; the frames carry each one exactly once, in order
    texts = [e["text"] for e in final["events"]]
    assert [e["n"] for e in final["events"]] == list(range(len(texts)))
    streamed = [e for f in frames for e in f["event_log"]]
    assert [e["n"] for e in streamed] == list(range(len(texts))) and [e["text"] for e in streamed] == texts
    assert texts[0].startswith("run started: reference 900 K in 3 s") and texts[-1] == "run finished"
    assert any("reference changed" in t for t in texts)
    # a page that read the history mid-run has a prefix of them; the frames after it bring the rest
    assert [e["text"] for e in hist["events"]] == texts[: len(hist["events"])]
    assert mid["change"].status_code == 200
    # the windows moved to the change: its first sample, 950 K, t_E = 1.5 s
    t0 = mid["change"].json()["applied_t"]
    for w in (final["windows"], detail["windows"]):  # the run's record and the server's change log agree
        assert w["setpoint"] == 950.0 and w["t0"] == pytest.approx(t0)
        assert w["steady"] == pytest.approx([t0 + 2.25, t0 + 3.0])


def test_frames_carry_spread_and_saturated_groups(tmp_path, small_cfg) -> None:
    with make_client(tmp_path, small_cfg) as c:
        run_id = c.post("/api/runs", json=RUN).json()["id"]
        frames = stream_frames(c, run_id)
    f = frames[-1]
    # the fake field is T + linspace(-5, 5) along x: over the fillet's columns the spread about the mean
    # is half the span of the fillet's x-centres times 10 K / (N_x - 1) steps
    nx = small_cfg.specimen.nx
    cols = [i for i in range(nx) if 0.25 <= (i + 0.5) / nx <= 0.75]
    ramp = np.linspace(-5, 5, nx)[cols]
    assert f["spread"] == pytest.approx((ramp.max() - ramp.min()) / 2, abs=0.05)
    assert f["saturated"] == [0] * 6  # the fake holds every group at 0.5


def test_a_repeated_start_request_starts_one_run(tmp_path, small_cfg) -> None:
    body = {**RUN, "duration": 60.0, "speed": 1.0}
    with make_client(tmp_path, small_cfg, SlowCheckFactory()) as c:
        key = {"Idempotency-Key": "click-1"}
        with concurrent.futures.ThreadPoolExecutor(2) as pool:  # a double click: both inside the slow check
            first, second = pool.map(lambda _: c.post("/api/runs", json=body, headers=key), range(2))
        assert sorted([first.status_code, second.status_code]) == [200, 201]
        assert first.json()["id"] == second.json()["id"]
        assert {first.json()["replayed"], second.json()["replayed"]} == {True, False}
        again = c.post("/api/runs", json=body, headers=key)  # a retry after the answer: still the same run
        assert again.status_code == 200 and again.json()["id"] == first.json()["id"]
        assert len(c.get("/api/runs").json()) == 1
        other = c.post("/api/runs", json={**body, "seed": 5}, headers=key)
        assert other.status_code == 409 and "another scenario" in other.json()["detail"]
        fresh = c.post("/api/runs", json=body, headers={"Idempotency-Key": "click-2"})
        assert fresh.status_code == 201 and fresh.json()["id"] != first.json()["id"]
        for r in c.get("/api/runs").json():
            c.post(f"/api/runs/{r['id']}/stop")


def test_a_refused_start_may_be_sent_again_with_the_same_id(tmp_path, small_cfg) -> None:
    with make_client(tmp_path, small_cfg) as c:
        key = {"Idempotency-Key": "k"}
        bad = c.post("/api/runs", json={**RUN, "reference": {"setpoint": 1280.0, "t_E": 3.0}}, headers=key)
        assert bad.status_code == 422  # the fake furnace holds at most 1250 K
        assert c.post("/api/runs", json=RUN, headers=key).status_code == 201


def test_label_and_delete(tmp_path, small_cfg) -> None:
    with make_client(tmp_path, small_cfg) as c:
        running = c.post("/api/runs", json={**RUN, "duration": 600.0, "speed": 1.0}).json()["id"]
        refused = c.delete(f"/api/runs/{running}")
        assert refused.status_code == 409 and "stop it" in refused.json()["detail"]
        c.post(f"/api/runs/{running}/stop")
        wait_status(c, running, {"stopped"})
        r = c.patch(f"/api/runs/{running}", json={"label": "  fixed,\tTC4 middle "})
        assert r.status_code == 200 and r.json()["label"] == "fixed, TC4 middle"
        assert c.get("/api/runs").json()[0]["label"] == "fixed, TC4 middle"
        assert c.patch(f"/api/runs/{running}", json={"label": "x" * 81}).status_code == 422
        assert c.patch(f"/api/runs/{running}", json={"label": "bell\x07"}).status_code == 422
        assert c.patch(f"/api/runs/{running}", json={"label": None}).json()["label"] is None
        folder = tmp_path / "data" / "runs" / running
        assert folder.is_dir()
        assert c.delete(f"/api/runs/{running}").status_code == 204
        assert not folder.exists() and not list(folder.parent.iterdir())  # no trash left behind
        assert c.get(f"/api/runs/{running}").status_code == 404 and c.get("/api/runs").json() == []
        assert c.delete(f"/api/runs/{running}").status_code == 404


def test_csv_and_report_exports(tmp_path, small_cfg) -> None:
    with make_client(tmp_path, small_cfg) as c:
        run_id = c.post("/api/runs", json=RUN).json()["id"]
        wait_status(c, run_id, {"finished"})
        c.patch(f"/api/runs/{run_id}", json={"label": "a/b test"})
        r = c.get(f"/api/runs/{run_id}/export.csv")
        z = np.load(io.BytesIO(c.get(f"/api/runs/{run_id}/timeseries").content))
        pdf = c.get(f"/api/runs/{run_id}/report.pdf")
        png = c.get(f"/api/runs/{run_id}/report.png")
        assert c.get(f"/api/runs/{run_id}/report.svg").status_code == 422
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    assert f'filename="a-b-test-{run_id}.csv"' in r.headers["content-disposition"]  # by label first
    rows = list(csv.reader(io.StringIO(r.text)))
    head, body = rows[0], rows[1:]
    for col in ("t_s", "eta_m", "T_ref_K", "T_mean_hat_K", "TC4_K", "TC4_hat_K", "u_T1h", "u_ff_T2v", "T_sup_K",
                "spread_K"):
        assert col in head, col
    assert len(body) == len(z["t"])
    np.testing.assert_allclose([float(row[head.index("T_mean_hat_K")]) for row in body], z["T_mean_hat"], rtol=1e-5)
    assert pdf.status_code == 200 and pdf.content[:5] == b"%PDF-" and len(pdf.content) > 10_000
    assert png.status_code == 200 and png.content[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("body, field, words", [
    ({"speed": "fast"}, "speed", "neither 'max' nor a number"),
    ({"reference": {"setpoint": "", "t_E": 10.0}}, "setpoint", "must be a number"),
    ({"duration": -5}, "duration", "must be above 0"),
    ({"oscillation": {"enabled": "maybe"}}, "enabled", "true or false"),
    ({"reference": {"setpint": 900.0}}, "setpint", "not a field"),
    ({"seed": 1.5}, "seed", "whole number"),
])
def test_refusals_are_plain_sentences(tmp_path, small_cfg, body, field, words) -> None:
    with make_client(tmp_path, small_cfg) as c:
        r = c.post("/api/runs", json=body)
    assert r.status_code == 422
    detail = r.json()["detail"]
    assert len(detail) == 1 and detail[0]["loc"][-1] == field and words in detail[0]["msg"], detail
    assert "Input should" not in r.text and "literal" not in detail[0]["msg"]


def test_glossary_explains_every_metric_and_term(tmp_path, small_cfg) -> None:
    with make_client(tmp_path, small_cfg) as c:
        g = c.get("/api/glossary").json()
    assert set(METRIC_KEYS) | {"coverage_2sigma_steady", "nees_mean", "late_samples"} <= set(g["metrics"])
    assert all(m["name"] and m["meaning"] and m["unit"] for m in g["metrics"].values())
    assert g["metrics"]["coverage_2sigma_steady"]["unit"] != g["metrics"]["mean_error_steady_max"]["unit"]
    for term in ("fillet", "t_E", "eta", "u_ff", "groups", "T_sup", "spread", "windows", "tc4", "saturation", "plant"):
        assert len(g["terms"][term]) > 40, term
    for group in small_cfg.lamps.groups:
        assert group.name in g["terms"]["groups"] and group.name in g["groups"]
    assert "h14, h13" in g["groups"]["T1h"]  # "h-1", "h-2": the last two horizontal lamps
