"""Recording formats: CSV table schemas (and, later, MCAP rollout logs)."""
