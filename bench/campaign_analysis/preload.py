"""Imported by the local cluster's fork server (cluster_host) before it forks any worker: distributed and what the
default step imports (fork_server.warm_up, with the garbage collector paused and the result frozen), so that no
worker imports them itself."""

from hilbench.bench.campaign_analysis.fork_server import warm_up

warm_up(("distributed",))
