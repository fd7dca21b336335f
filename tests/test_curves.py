"""benchmark/aggregate.py's learning curves: the curve data against hand-computed figures, the picture, the link on the results page,
and the per-regime curves of benchmark/regime_summary.py."""
from pathlib import Path

import pytest
from conftest import plant, plant_expert, summarise

from benchmark import aggregate
from benchmark.aggregate import Curve, Record

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture
def runs(tmp_path):
    """Hopper: BC-OH seeds 1 and 2 evaluated at epochs 1, 2 with returns 10, 30 and 20, 50; C2F seed 1 with 5, 7, 9.
    Ant: C2F seed 1 with 100. Experts: Hopper 1000 (one evaluation, at epoch 0)."""
    runs = tmp_path / "runs"
    plant(runs, "bc_oh", "Hopper-v4", 1, [10.0, 30.0])
    plant(runs, "bc_oh", "Hopper-v4", 2, [20.0, 50.0])
    plant(runs, "c2f", "Hopper-v4", 1, [5.0, 7.0, 9.0])
    plant(runs, "c2f", "Ant-v4", 1, [100.0])
    plant_expert(runs, "Hopper-v4", 1000.0)
    return runs


def test_curves_by_hand_and_the_expert_is_no_curve(runs):
    records, problems = aggregate.collect(runs, allow_nonpaper=False)
    assert problems == [] and len(records) == 5
    data = aggregate.curves(records)
    assert list(data) == ["Hopper-v4", "Ant-v4"]  # the paper's env order
    assert list(data["Hopper-v4"]) == ["bc_oh", "c2f"]  # no "expert": it is a dashed line, not a curve
    assert data["Hopper-v4"]["bc_oh"] == ([1, 2], [15.0, 40.0], [10.0, 30.0], [20.0, 50.0])  # epochs, mean, min, max
    assert data["Hopper-v4"]["c2f"] == Curve([1, 2, 3], [5.0, 7.0, 9.0], [5.0, 7.0, 9.0], [5.0, 7.0, 9.0])  # one seed: no band
    assert data["Ant-v4"] == {"c2f": Curve([1], [100.0], [100.0], [100.0])}
    assert aggregate.expert_scores(records) == {"Hopper-v4": 1000.0}


def test_seeds_evaluated_at_other_epochs_are_averaged_only_where_all_have_a_point():
    def record(seed, evaluations):
        return Record("bc_oh", "Hopper-v4", seed, 0.0, Path("x"), evaluations=evaluations)

    records = [record(1, [[100, 10.0], [200, 30.0], [300, 40.0]]), record(2, [[100, 20.0], [200, 50.0]]),
               record(3, [[50, 1.0], [100, 30.0], [200, 70.0]])]
    assert aggregate.curves(records) == {"Hopper-v4": {"bc_oh": ([100, 200], [20.0, 50.0], [10.0, 30.0], [30.0, 70.0])}}
    assert aggregate.curves(records[:2] + [record(3, [[50, 1.0]])]) == {}  # no epoch common to all seeds: no curve
    assert aggregate.curves([Record("expert", "Hopper-v4", 0, 1.0, Path("x"), evaluations=[[0, 1.0]])]) == {}


def test_the_aggregator_writes_the_curves_and_links_them_in_the_page(runs, tmp_path, capsys):
    out, page = tmp_path / "results", tmp_path / "page.md"
    page.write_text("# Title\n\n<!-- table2 -->\nthe old table\n<!-- /table2 -->\n\nReading.\n")
    assert aggregate.main(["--results-dir", str(runs), "--out", str(out), "--page", str(page)]) == 0
    assert (out / "curves.png").read_bytes()[:8] == PNG
    assert not list(out.glob("*.tmp*")), "written atomically: no temporary file left"
    assert f"{out / 'curves.png'}" in capsys.readouterr().out
    assert page.read_text().endswith(
        "\n\n![Table 2](results/table2.png)\n\n![Learning curves](results/curves.png)\n<!-- /table2 -->\n\nReading.\n")


def test_without_curves_nothing_is_drawn_or_linked(tmp_path):
    runs, out, page = tmp_path / "runs", tmp_path / "results", tmp_path / "page.md"
    plant_expert(runs, "Hopper-v4", 1000.0)
    page.write_text("<!-- table2 -->\n<!-- /table2 -->\n")
    assert aggregate.main(["--results-dir", str(runs), "--out", str(out), "--page", str(page)]) == 0
    assert not (out / "curves.png").exists() and "curves.png" not in page.read_text()
    assert page.read_text().endswith("\n\n![Table 2](results/table2.png)\n<!-- /table2 -->\n")


def test_the_regime_summary_writes_curves_per_regime(regime_map, capsys):
    results, experts, _ = regime_map
    assert summarise(results, experts) == 0
    for regime in ("native_noise", "fs1_noise"):
        assert (results / regime / "curves.png").read_bytes()[:8] == PNG
    assert not (results / "native_hidden" / "curves.png").exists()
