"""Stochastic averaging of the energy envelope: symbolic coefficients, stationary and transient densities."""
