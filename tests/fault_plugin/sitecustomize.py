"""Loaded at the start of every Python process the tests start (conftest puts this
directory first on PYTHONPATH): with KNITSWEEP_TEST_SIGNAL_AT set, install the tests'
fault injector (fault_injection.py); otherwise nothing."""

import os

if os.environ.get("KNITSWEEP_TEST_SIGNAL_AT"):
    import fault_injection

    fault_injection.install()
