"""The name of a campaign folder's index (``index.json``: one entry per run, docs/campaign.md), in a module of its
own, outside the acquisition layer: the campaign analysis and ``hilbench analyse``'s early cluster start read it
without importing numpy and the campaign runner (acquisition.campaign, its runner, drivers and plans: 0.1-0.2 s on
the local cluster's start-up path)."""

from __future__ import annotations

#: the campaign folder's index file
INDEX_NAME = "index.json"
