"""Estimators of the Bayesian objective: Monte Carlo, linearised and importance sampling."""
