"""File boundaries: BVH motion, audio decoding, atomic writes."""
