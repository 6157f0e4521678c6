# pytest collects the doctests of the docs' Markdown pages (see pyproject's doctest glob); these are not pages
collect_ignore = ["conf.py", "_build", "api", "tutorials", "jupyter_execute"]
