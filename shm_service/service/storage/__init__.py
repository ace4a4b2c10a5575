"""What the service stores, behind one interface (``Storage``): trends, alarms and their outbox,
state and baselines, fatigue, the reprocess ledger, paging and retention, and the one writer of a
fleet's database. One subfolder per database engine holds what is specific to it (``sqlite``); a new
backend is a sibling folder. May import ``contract``; nothing else of the service.
"""
