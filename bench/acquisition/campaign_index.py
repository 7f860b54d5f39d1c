"""The name of a campaign folder's index (``index.json``: one entry per run, docs/campaign.md), in a module of its
own: the campaign analysis and ``hilbench analyse``'s early cluster start read it without importing the campaign
runner (acquisition.campaign and its runner, drivers and plans: 40-70 ms, on the local cluster's start-up path)."""

from __future__ import annotations

#: the campaign folder's index file
INDEX_NAME = "index.json"
