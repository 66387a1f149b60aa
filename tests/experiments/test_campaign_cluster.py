"""The campaign's runs on the study engine's cluster (issue 21): what goes wrong says so in a line, and a worker
never ray-traces a radiation table.  The runs themselves on a LocalCluster: ``test_campaign.py``."""

from __future__ import annotations

import socket

import pytest

from furnace_twin.cli import build_parser, main
from twin.config import small_config
from twin.experiments import campaign_runs
from twin.experiments.campaign import run_campaign
from twin.experiments.campaign_runs import CampaignRun, TablesNotCached, furnace_tables, group_by_plan


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_a_worker_without_the_tables_says_so_instead_of_ray_tracing(tmp_path, monkeypatch):
    cfg = small_config()
    monkeypatch.setenv("FURNACE_TWIN_CACHE", str(tmp_path))  # an empty cache: a worker on a fresh machine
    monkeypatch.setattr(campaign_runs, "_TABLES", {})
    with pytest.raises(TablesNotCached, match="furnace-twin precompute") as exc:
        furnace_tables(cfg.digest(), cfg.model_dump(mode="json"), truth=True)
    assert str(tmp_path) in str(exc.value)
    assert not list(tmp_path.iterdir())  # nothing traced, nothing written


def test_runs_that_share_their_first_plan_go_to_one_worker():
    names = [f"{m}_tc4_{x}" for m in ("fixed", "oscillating") for x in ("0.375", "0.5", "0.625")]
    tasks = [CampaignRun(n, s, f"/o/{n}/seed_{s}", "{}", "d", own_truth=True) for n in names for s in (0, 1)]
    groups = group_by_plan(tasks)
    # 2 modes x 2 seeds; the oscillating (longer) runs first; each group one mode and seed, its 3 TC4 positions
    assert [(g[0].name.split("_")[0], g[0].seed) for g in groups] == [
        ("oscillating", 0), ("oscillating", 1), ("fixed", 0), ("fixed", 1)]
    for g in groups:
        assert len({(t.name.split("_")[0], t.seed) for t in g}) == 1 and len(g) == 3
    assert sorted((t.name, t.seed) for g in groups for t in g) == sorted((t.name, t.seed) for t in tasks)  # all, once


def test_unreachable_scheduler_exits_2_with_a_line(tmp_path, capsys, monkeypatch):
    import twin.studies.cluster as cluster

    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT_S", 1.0)
    address = f"tcp://127.0.0.1:{_free_port()}"
    assert main(["campaign", "--scheduler", address, "--seeds", "1", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "furnace-twin campaign: cannot reach the Dask scheduler" in err and "Traceback" not in err
    assert not (tmp_path / "o" / "campaign.json").exists()


@pytest.mark.parametrize("argv", [["campaign", "--workers", "0"], ["campaign", "--workers", "two"],
                                  ["campaign", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"]])
def test_bad_workers_are_argparse_errors(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(argv)
    assert exc.value.code == 2 and "--workers" in capsys.readouterr().err


def test_a_negative_worker_count_is_refused(tmp_path):
    with pytest.raises(ValueError, match="workers must be >= 0"):
        run_campaign(small_config(), tmp_path, workers=-1)


def test_the_local_clusters_workers_keep_glibcs_malloc_trim():
    """dask's nannies set MALLOC_TRIM_THRESHOLD_=65536 in their workers; the study engine's LocalCluster does not
    (it tripled the campaign's system time, twin.studies.cluster.NO_MALLOC_TRIM)."""
    import os

    from twin.studies.cluster import study_client

    with study_client(workers=1) as (client, n):
        env = client.run(lambda: os.environ.get("MALLOC_TRIM_THRESHOLD_"))
    assert n == 1 and list(env.values()) == [None]
