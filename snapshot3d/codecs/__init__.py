"""The torch-free parts of both media's codecs (numpy and OpenCV): what the embedder writes and the
decoder reads, on both sides of the phone.

- `media`: the shared interface: one `Medium` per medium (its codec ids and plane limits), `medium_of(codec)`;
- the `file` medium: `file_layout` (where the planes sit in its network's secret);
- the `print` medium: `bands` (the orthonormal band split), `print_source` (the planes' DCT and the power
  each coefficient gets), `print_carriers` (the layout: carriers, pilots, the brightness-shaped filters),
  `print_embed`, `print_read` (the designed receiver), `print_fold` (`print-2`'s folded carriers),
  `print_feeds` (the layout as the restore graph's inputs) and `print_channel` (the capture channel's model).

Nothing is imported here: import the submodule you need."""

__all__ = ["media", "file_layout", "bands", "print_source", "print_carriers", "print_embed", "print_read",
           "print_fold", "print_feeds", "print_channel"]
