"""What a fit writes: results.json, the paper's Table 2, plots."""
