"""snapshot3d: a 3D scene printed as a photograph, and a phone photo of the print turned back into 3D.

Subpackages: `train` (torch: fitting, codec training), `export` (torch -> ONNX), `scanner` and
`viewer` (the torch-free decode path). Shared maths and formats live at this level.
"""
__version__ = "0.1.0"
__all__ = ["__version__"]
