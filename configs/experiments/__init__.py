"""Experiment variants of the configs a user runs (the campaign's arms, docs/campaign.md)."""
