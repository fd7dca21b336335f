"""The Table 2 benchmark: run methods x envs x seeds (run_grid), then tabulate and plot (aggregate).

    python -m benchmark.run_grid --methods bc_so bc_oh c2f --envs Hopper-v4 --seeds 1 2 3 --workers 2
    python -m benchmark.aggregate --results-dir results/runs --out results

paper.py holds the paper's numbers and settings, results.py reads and checks per-run JSON results.
"""
