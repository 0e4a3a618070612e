"""What a run writes: report.json and its schema, the review page, maps, CSV tables."""
