"""Reference curves, disturbances, the stepping engine, results and metrics."""
