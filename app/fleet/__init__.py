"""`headway fleet`: many drives replayed through the whole stack in parallel on Dask, one report
(docs/fleet.md). manifest.py the drives and their keys, drive.py one drive in a worker, engine.py the Dask
cluster, run.py the command, report.py the report, compare.py two runs against each other."""
