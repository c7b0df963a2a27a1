"""Presenting results: JSON summaries, time series, figures, the reproduction report, and
writing all of them without leaving partial files (see :mod:`popdispatch.report.output`)."""
