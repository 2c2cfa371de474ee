"""Importers of public tactile data sets: each turns a data set's own files into the observations
of a feature table (docs/feature-tables.md), so that aptkt learns from real sensors' data."""
