"""Show files: loading with line marks, schema and semantic checks, and the compiled plan."""
