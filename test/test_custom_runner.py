"""GraspGuide custom PlatformIO test runner: GoogleTest without the registry.

platformio.ini sets ``test_framework = custom`` for every environment, so
PlatformIO loads this file and instantiates ``CustomTestRunner``.  It is
PlatformIO's built-in GoogleTest runner (same console output, same result
parsing) except that:

* it declares no ``EXTRA_LIB_DEPS`` -- the stock runner would install
  ``google/googletest`` from the PlatformIO registry, which is unreachable;
* on the host it links Debian's libgtest-dev static libraries
  (/usr/lib/x86_64-linux-gnu/libgtest{,_main}.a) and pthread.  ``main()``
  comes from gtest_main unless a test file defines its own (a static archive
  member is only pulled in when still needed, so both work);
* a GoogleTest program that ran to its end and exits with code 1 because
  some test failed is reported as those FAILED cases only.  The stock runner
  additionally adds an ERRORED pseudo-case ("Program received signal SIGHUP",
  a misreading of exit code 1), which would double-count the failure.  Any
  other non-zero exit (crash, abort, exit before the end) still ERRORs.
"""

import signal

from platformio.test.exception import UnitTestError
from platformio.test.result import TestStatus
from platformio.test.runners.googletest import GoogletestTestRunner
from platformio.test.runners.readers.native import NativeTestOutputReader


class _GtestNativeReader(NativeTestOutputReader):
    def __init__(self, test_runner):
        super().__init__(test_runner)
        # gather_results() calls self.raise_for_status(code) on non-zero exit
        self.raise_for_status = self._raise_for_status

    def _raise_for_status(self, return_code):
        suite = self.test_runner.test_suite
        if (
            return_code == 1
            and suite.is_finished()  # gtest printed its final tear-down line
            and suite.get_status_nums(TestStatus.FAILED) > 0
        ):
            return  # the ordinary "some tests failed" exit of GoogleTest
        if return_code < 0:
            try:
                name = signal.Signals(-return_code).name
            except ValueError:
                name = "signal %d" % -return_code
            raise UnitTestError("Test program was killed by %s" % name)
        raise UnitTestError(
            "Test program exited with code %d before GoogleTest finished "
            "(or without any failed test)" % return_code
        )


class CustomTestRunner(GoogletestTestRunner):
    # Never ask the registry for a test-framework library.
    EXTRA_LIB_DEPS = None

    def configure_build_env(self, env):
        env = super().configure_build_env(env)
        if not self.platform.is_embedded():
            # gtest_main must precede gtest on the link line.
            env.Append(
                LIBS=["gtest_main", "gtest", "pthread"],
                CCFLAGS=["-pthread"],
                LINKFLAGS=["-pthread"],
            )
        return env

    def stage_testing(self):
        native = not self.platform.is_embedded() and not self.get_test_port()
        custom_cmd = self.project_config.get(
            f"env:{self.test_suite.env_name}", "test_testing_command"
        )
        if self.options.without_testing or not native or custom_cmd:
            return super().stage_testing()
        import click  # pylint: disable=import-outside-toplevel

        click.secho("Testing...", bold=True)
        return _GtestNativeReader(self).begin()
