"""Fitting fault models to evidence: a grid for time offsets then least squares, forward selection on BIC, and
what each fault found is worth (Shapley shares, bootstrap intervals)."""
