"""The safe states side by side on a reduced spec (profiles/faults/safe_states.toml) on 2 worker processes: its wall
time, and its tables are the ones docs/safety.md quotes (host_tools/reports/doc_figures.py; --benchmark-only)."""

from __future__ import annotations

from host_tools.reports import doc_figures


def test_bench_safe_states_campaign_and_its_tables_in_the_docs(benchmark):
    blocks = {"safe_states_campaign": doc_figures.safe_states_campaign}
    stale: list[str] = []
    benchmark.pedantic(lambda: stale.extend(doc_figures.check(blocks=blocks)), rounds=1, iterations=1)
    assert stale == [], "run: python -m host_tools.reports.doc_figures --write --bench"
