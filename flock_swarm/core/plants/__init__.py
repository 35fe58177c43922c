"""Plant models: what the agents physically are (double integrator, velocity lag, unicycle)."""
