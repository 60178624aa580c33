"""Recording formats: CSV tables, training curves, MCAP rollout logs, offscreen videos."""
