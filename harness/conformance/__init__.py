"""The conformance battery (``contactbench validate``): its cases (``cases``), the
battery and its verdict table (``battery``), the Markdown report (``report``) and the
command line (``command``)."""
