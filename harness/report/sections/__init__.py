"""The report's sections: every module here is imported by the section registry
(harness/report/core.py) on first use and registers its sections with
``@register_section``."""
