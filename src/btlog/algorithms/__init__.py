"""General algorithms with no knowledge of behavior trees."""
