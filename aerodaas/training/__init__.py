"""Training and fine-tuning AeroDaaS's detectors on a user's own labelled imagery (``aerodaas train detector``).

Needs the optional ``[train]`` extra (PyTorch's CPU build: ``pip install -e ".[train]"``, see docs/training.md).
Nothing outside this sub-package and the ``train`` command imports it, so the framework runs without PyTorch.
"""
