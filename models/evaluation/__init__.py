"""Evaluation: the paper's metrics (evaluate.py), cross-validation (crossval.py), the live system
replayed through the host (temporal.py, temporal_scores.py), coverage maps (coverage.py) and
plots (plots.py)."""

__all__: list[str] = []
