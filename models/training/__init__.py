"""Training (train.py, torch behind the ``train`` extra), ensembles (ensemble.py), and ONNX
export and int8 quantisation (export.py)."""

__all__: list[str] = []
