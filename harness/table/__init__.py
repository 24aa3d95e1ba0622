"""The stored table: its columns (``schema``), the journal's rows (``journal``), table
files, results folders and run lock (``store``), meta.json (``meta``), field files
(``fields``), aggregates read from a table (``aggregates``) and the one home of atomic
writes, safe names and canonical JSON (``files``).  It imports nothing else from the
harness."""
