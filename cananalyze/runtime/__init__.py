"""Run-time support: the optional compiled helper, allocator and GC policy."""
