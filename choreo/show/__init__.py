"""Show files: a file's bytes to a checked `Show`, and the `Plan` the runner walks.

`load` runs the passes in order: `read` (bytes to located plain data, through `yamlwalk`,
`scalars` and `nesting`), `schema` (the JSON Schema's findings in a show author's words),
`checks` (what a schema cannot say), `build` (the records); they share `report`. `model` holds
the records, `plan` compiles them per robot, `hth4` and `starter` make a show from a Heart to
Heart 4 project."""
