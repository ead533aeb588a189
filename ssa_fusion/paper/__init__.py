"""The AAS 25-577 study: scenarios, simulation, Monte Carlo, the experiments, plots."""
