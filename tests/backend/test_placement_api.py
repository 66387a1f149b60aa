"""``/api/placement``: TC placement for the Studies view (issue 25, Remark 3).

The ranking itself (``twin.experiments.place_tcs.rank_positions``) is tested in tests/estimation/test_placement.py
and end to end in the Studies view's browser test; here a recording stand-in takes its place, so what is checked
is the plumbing: one ranking per mode made in the background and kept, ``count`` as the first positions of it,
a failure reported and retried, bad input 4xx, the token.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.settings import Settings
from backend.studies.placement import RANKED
from conftest import fake_factory

TOKEN = "placement-token-0123456789"


class StandIn:
    """rank_positions' shape: six positions with growing scores, the paper's baseline, a 3 x 2 map."""

    def __init__(self, fail: int = 0, hold: threading.Event | None = None) -> None:
        self.calls: list[dict] = []
        self.fail, self.hold = fail, hold

    def __call__(self, cfg, *, count, oscillate, radiation) -> dict:
        self.calls.append({"count": count, "oscillate": oscillate, "radiation": radiation})
        if self.hold is not None:
            self.hold.wait(10.0)
        if len(self.calls) <= self.fail:
            raise RuntimeError("the plan failed")
        pos = [{"x": 0.04 * (k + 1), "y": 0.1, "x_rel": 0.1 * (k + 1), "y_rel": 0.5,
                "score": 10.0 * (k + 1) + oscillate} for k in range(count)]
        return {"positions": pos, "criterion": "information (test)", "oscillate": oscillate,
                "baseline": {"paper": 25.0, "paper_positions": [[0.25, 0.5], [0.5, 0.8], [0.75, 0.5]]},
                "map": {"rel": [[0.2, 0.3], [0.5, 0.3], [0.8, 0.3], [0.2, 0.7], [0.5, 0.7], [0.8, 0.7]],
                        "score": [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]}}


class WithRadiation(type(fake_factory())):
    """The conftest's stand-in loop with a radiation model to hand to the ranking."""

    table = object()

    def radiation(self, cfg):
        return self.table


def client(tmp_path: Path, cfg, rank, factory=None, **settings) -> TestClient:
    s = Settings(data_dir=tmp_path / "data", **settings)
    app = create_app(s, cfg, loop_factory=factory or WithRadiation(), placement_rank=rank)
    return TestClient(app, base_url="http://127.0.0.1")


def wait_done(c: TestClient, **params) -> dict:
    end = time.monotonic() + 20.0
    while time.monotonic() < end:
        body = c.get("/api/placement", params=params).json()
        if body["state"] != "computing":
            return body
        time.sleep(0.05)
    raise AssertionError(f"the placement never finished: {body}")


def test_nothing_before_it_is_asked_for_then_one_ranking_per_mode_kept(tmp_path, small_cfg) -> None:
    rank = StandIn()
    with client(tmp_path, small_cfg, rank) as c:
        r = c.get("/api/placement")
        assert r.status_code == 404 and "POST /api/placement" in r.json()["detail"]
        r = c.post("/api/placement", json={})
        assert r.status_code == 202 and r.json()["oscillate"] is False
        body = wait_done(c)
        assert body["state"] == "done" and body["furnace"] == "custom" and body["count"] == 3
        assert [p["rank"] for p in body["positions"]] == [1, 2, 3]
        assert [p["score"] for p in body["positions"]] == [10.0, 20.0, 30.0]
        assert body["paper"] == {"positions": [[0.25, 0.5], [0.5, 0.8], [0.75, 0.5]], "score": 25.0}
        assert body["map"]["x_rel"][:3] == [0.2, 0.5, 0.8] and body["map"]["y_rel"][3] == 0.7
        assert body["map"]["score"] == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0] and body["seconds"] >= 0.0
        # every count is the first positions of the one ranking of RANKED (greedy's choices do not depend on it)
        assert [p["x_rel"] for p in wait_done(c, count=1)["positions"]] == [0.1]
        assert len(wait_done(c, count=RANKED)["positions"]) == RANKED
        assert c.post("/api/placement", json={"oscillate": False}).json()["state"] == "done"  # kept, not redone
        assert c.get("/api/placement", params={"oscillate": True}).status_code == 404
        c.post("/api/placement", json={"oscillate": True})
        osc = wait_done(c, oscillate=True)
        assert osc["oscillate"] is True and osc["positions"][0]["score"] == 11.0
    assert [(k["count"], k["oscillate"]) for k in rank.calls] == [(RANKED, False), (RANKED, True)]
    assert all(k["radiation"] is WithRadiation.table for k in rank.calls)  # the twin's own radiation model


def test_while_it_is_made_the_state_says_so_and_a_second_post_does_not_start_another(tmp_path, small_cfg) -> None:
    hold = threading.Event()
    rank = StandIn(hold=hold)
    with client(tmp_path, small_cfg, rank) as c:
        assert c.post("/api/placement", json={}).json()["state"] == "computing"
        body = c.get("/api/placement").json()
        assert body["state"] == "computing" and body["positions"] == [] and body["seconds"] is None
        assert c.post("/api/placement", json={}).json()["state"] == "computing"
        hold.set()
        assert wait_done(c)["state"] == "done"
    assert len(rank.calls) == 1


def test_a_failed_ranking_says_why_and_a_new_post_tries_again(tmp_path, small_cfg) -> None:
    rank = StandIn(fail=1)
    with client(tmp_path, small_cfg, rank) as c:
        c.post("/api/placement", json={})
        body = wait_done(c)
        assert body["state"] == "failed" and body["error"] == "RuntimeError: the plan failed"
        assert body["positions"] == [] and body["paper"] is None
        assert c.post("/api/placement", json={}).status_code == 202
        assert wait_done(c)["state"] == "done"
    assert len(rank.calls) == 2


def test_a_loop_without_a_radiation_model_fails_in_words_not_a_500(tmp_path, small_cfg) -> None:
    with client(tmp_path, small_cfg, StandIn(), factory=fake_factory()) as c:
        assert c.post("/api/placement", json={}).status_code == 202
        body = wait_done(c)
        assert body["state"] == "failed" and "no radiation model" in body["error"]


def test_bad_input_is_a_4xx_and_the_token_is_needed_to_start(tmp_path, small_cfg) -> None:
    with client(tmp_path, small_cfg, StandIn(), api_token=TOKEN) as c:
        assert c.post("/api/placement", json={}).status_code == 401
        auth = {"X-API-Token": TOKEN}
        assert c.post("/api/placement", json={"oscillate": "sometimes"}, headers=auth).status_code == 422
        assert c.post("/api/placement", json={"count": 3}, headers=auth).status_code == 422  # extra field
        for count in (0, RANKED + 1):
            assert c.get("/api/placement", params={"count": count}, headers=auth).status_code == 422
        assert c.post("/api/placement", json={"oscillate": True}, headers=auth).status_code == 202
