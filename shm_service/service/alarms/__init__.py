"""The service's alarms once the engine has raised them: the alarm changes written with a window's
commit (``_changes``), their delivery from the outbox to webhooks and e-mail (``_notify``), and the
isolation of the sinks that may fail, the notifier and the dashboard (``_sinks``).
May import ``contract``, ``analytics`` and ``storage``; nothing above them.
"""
