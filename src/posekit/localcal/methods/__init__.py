"""The paper's local-calibration methods: orientation adjustment (eq. 7–8), line-equation range
adjustment on the circular path (eq. 10–16), trajectory-matching range adjustment (eq. 17–22)."""
