"""The missing-dependency policy (tests/dependency_policy.py): a skip with the reason locally, a failure under CI.

Each case runs a tiny inner test session with pytest's `pytester`, once with `CI=true` and once without.
"""

import pytest

pytest_plugins = ["pytester"]

NO_SUCH_MODULE = "cama_no_such_module_for_the_policy_test"


@pytest.fixture
def ci(monkeypatch: pytest.MonkeyPatch) -> None:
    """The inner run is under CI."""
    monkeypatch.setenv("CI", "true")


@pytest.fixture
def local(monkeypatch: pytest.MonkeyPatch) -> None:
    """The inner run is not under CI (even when the outer one is)."""
    monkeypatch.delenv("CI", raising=False)


def inner_test_needing_the_module(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(
        f"""
        from tests.dependency_policy import require_module

        def test_needs_it():
            require_module("{NO_SUCH_MODULE}")
        """
    )


@pytest.mark.usefixtures("ci")
def test_a_missing_module_fails_under_ci_naming_it_and_how_make_test_installs_it(
    pytester: pytest.Pytester,
) -> None:
    inner_test_needing_the_module(pytester)
    result = pytester.runpytest()
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(
        [f"*missing dependency: Python module '{NO_SUCH_MODULE}'*`make test` installs it*"]
    )


@pytest.mark.usefixtures("local")
def test_a_missing_module_skips_locally_with_the_reason(pytester: pytest.Pytester) -> None:
    inner_test_needing_the_module(pytester)
    result = pytester.runpytest("-rs")
    result.assert_outcomes(skipped=1)
    result.stdout.fnmatch_lines([f"SKIPPED*missing dependency: Python module '{NO_SUCH_MODULE}'*"])


def test_a_module_level_requirement_skips_the_module_locally_and_is_a_collection_error_under_ci(
    pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch
) -> None:
    pytester.makepyfile(
        f"""
        from tests.dependency_policy import require_module

        module = require_module("{NO_SUCH_MODULE}")

        def test_uses_it():
            pass
        """
    )
    monkeypatch.delenv("CI", raising=False)
    pytester.runpytest().assert_outcomes(skipped=1)
    monkeypatch.setenv("CI", "true")
    result = pytester.runpytest()
    result.assert_outcomes(errors=1)
    result.stdout.fnmatch_lines([f"*missing dependency: Python module '{NO_SUCH_MODULE}'*"])


def test_a_missing_program_skips_locally_and_fails_under_ci_naming_it(
    pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch
) -> None:
    pytester.makepyfile(
        """
        import pytest
        from tests.dependency_policy import require_program

        @pytest.fixture
        def tool():
            return require_program("/nonexistent/cama-tool", "the test runs it", "`make test` installs it")

        def test_runs_the_tool(tool):
            pass
        """
    )
    monkeypatch.delenv("CI", raising=False)
    pytester.runpytest().assert_outcomes(skipped=1)
    monkeypatch.setenv("CI", "true")
    result = pytester.runpytest()
    result.assert_outcomes(errors=1)
    result.stdout.fnmatch_lines(["*missing dependency: program /nonexistent/cama-tool (the test runs it)*"])


def test_the_safety_net_fails_any_skip_under_ci_but_not_locally_and_leaves_xfail_alone(
    pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch
) -> None:
    pytester.makepyfile(
        test_skips=f"""
        import pytest

        def test_importorskip():
            pytest.importorskip("{NO_SUCH_MODULE}")

        def test_plain_skip():
            pytest.skip("no reason given here")

        @pytest.mark.xfail(reason="known", strict=True)
        def test_expected_failure():
            assert False
        """,
        test_module_skip=f"""
        import pytest

        pytest.importorskip("{NO_SUCH_MODULE}")
        """,
    )
    monkeypatch.delenv("CI", raising=False)
    pytester.runpytest("-p", "tests.dependency_policy").assert_outcomes(skipped=3, xfailed=1)
    monkeypatch.setenv("CI", "true")
    result = pytester.runpytest("-p", "tests.dependency_policy", "--continue-on-collection-errors")
    result.assert_outcomes(failed=2, errors=1, xfailed=1)
    result.stdout.fnmatch_lines(
        [
            f"*skipped under CI=true, where nothing may skip: could not import '{NO_SUCH_MODULE}'*",
            "*skipped under CI=true, where nothing may skip: no reason given here*",
        ]
    )


def test_the_suite_runs_under_the_policy(pytestconfig: pytest.Config) -> None:
    """tests/conftest.py registers the safety net for every test of the suite."""
    assert pytestconfig.pluginmanager.has_plugin("tests.dependency_policy")
