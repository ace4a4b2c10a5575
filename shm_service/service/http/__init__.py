"""The HTTP API of the service: the app built by construction (``_app``: routers, dependencies,
exception handlers), its door (``_gate``: host checks, tokens, rate limits), the shared paging and
error conventions (``_pages``, ``_common``), the offline API documents (``_docs``), ``/metrics``
(``_metrics``) and uvicorn in a thread (``_server``). A new route goes into ``routes``. The API
talks to the runtime only through ``contract.ServicePort``; it may import ``contract`` and the
storage's read types, never the runtime's classes.
"""
