"""Drift of identified parameters over a campaign: covariate fit, EWMA and CUSUM charts, change points
(docs/campaign-analysis.md). Reads the results table of ``hilbench analyse``; never touches a device."""
