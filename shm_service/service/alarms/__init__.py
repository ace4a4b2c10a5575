"""The service's alarms once the engine has raised them: the alarm changes written with a window's
commit (``_changes``) and their delivery from the outbox to webhooks and e-mail (``_notify``).
May import ``contract``, ``analytics`` and ``storage``; nothing above them.
"""
