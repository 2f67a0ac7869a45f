"""Test and benchmark rigs: programs that exercise the library, not parts of it.

* :mod:`~railpilot.rigs.loadtest` - N trains against one ground server on loopback
  (``railpilot link loadtest``, benchmarks/front_server_capacity.py);
* :mod:`~railpilot.rigs.page_probe` - the dispatcher page in headless chromium, counting
  its renders (the load test's ``--dashboard``).

They sit above every other package: they drive the link adapters (net/) and the dashboard
(web/) together. No library module imports them; only the command that runs them, tests and
benchmarks do (tests/test_import_layers.py checks that).
"""
