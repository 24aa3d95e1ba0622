"""Running a benchmark: the plan (``plan``, ``studies``, ``skips``), the jobs and their
reference answers (``job``, ``rows``), the isolated solve (``worker``, ``isolation``),
the executors (``executors``, ``distributed``), the run (``runner``) and load histories
in a script (``sequence``).  It writes the table (harness/table/) and never imports the
report."""
