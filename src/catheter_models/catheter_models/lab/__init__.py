"""The model lab: compare a model with measurements, locate where it fails, diagnose missing physical effects (docs/lab.md), add them, and keep the history."""  # noqa: E501
