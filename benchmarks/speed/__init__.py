"""Speed and memory benchmarks: hdrio against its peers and the floor, in one process.

``python -m benchmarks.speed`` (see docs/speed.md). Every row is timed in the same run as
its baseline, so the reported ratios hold whatever the machine's load.
"""
