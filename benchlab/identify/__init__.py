"""Grey-box identification of thermal networks from run files (output-error, nonlinear least squares)."""
