"""Trials: the harness (build once, reset per trial, score) and the scenario runner."""
