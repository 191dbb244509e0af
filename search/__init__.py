"""Worst-case search over a study's space for the violation of STL requirements
(docs/search.md): ``python -m search run FILE`` (``make search``)."""
