"""Studies on any drive, through the drive protocol: laws, error models, Monte Carlo, sensitivities."""
