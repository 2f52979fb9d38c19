"""Training and fine-tuning AeroDaaS's detectors on a user's own labelled imagery (``aerodaas train detector``).

Needs the optional ``[train]`` extra (PyTorch's CPU build: ``pip install -e ".[train]"``, see docs/training.md).
Nothing outside this sub-package, the ``train`` command and ``aerodaas label`` (the labelled-set readers, which need
no PyTorch) imports it, so the framework runs without PyTorch.
"""
