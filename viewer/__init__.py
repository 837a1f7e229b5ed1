"""The phone side: restore and render with onnxruntime (numpy, OpenCV, onnxruntime; never torch).

Public surface: `decode_photo(path)` (viewer.decode; `path` a list: several photos of one print, combined by
`viewer.burst`), `render_views`, `RenderConfig` (viewer.render),
`session`, `model_path` (viewer.runtime)."""

__all__ = ["decode_photo", "render_views", "RenderConfig", "session", "model_path"]

_WHERE = {"decode_photo": "decode", "render_views": "render", "RenderConfig": "render", "session": "runtime",
          "model_path": "runtime"}


def __getattr__(name):
    from importlib import import_module
    if name in _WHERE:
        return getattr(import_module(f"{__name__}.{_WHERE[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
