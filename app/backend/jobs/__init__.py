"""Background jobs: an in-process runner (`runner.py`) and the job kinds it can run (`kinds.py`)."""
