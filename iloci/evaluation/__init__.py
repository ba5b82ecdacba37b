"""Cross-validation, metrics, figures and the report (the paper's experiment)."""
