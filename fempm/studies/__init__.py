"""Studies: scripts-as-functions that write tables and figures (run with ``python -m fempm study``)."""
