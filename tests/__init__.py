"""The test suite as a package: helpers are imported by their package path (`from tests.vma.vma_test_sites import
...`), never through `sys.path` inserts, and `tests/annotations` is `tests.annotations`, so it cannot shadow the real
`annotations` package. pytest puts the repository root on `sys.path` (pyproject: `pythonpath = ["."]`)."""
