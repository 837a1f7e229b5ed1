"""The print sheet, the print-and-capture simulator and the scanner (numpy and OpenCV only; never torch)."""
__all__: list[str] = []
