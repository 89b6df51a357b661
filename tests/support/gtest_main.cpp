// The test executables' main: GoogleTest's, except that a run in which every test skipped exits 77,
// the skip code of the ctest tests that run a whole suite (cmake/test_suites.cmake): such a test
// shows as skipped only when nothing in it ran, and a failure beside a skip still fails it.
#include <gtest/gtest.h>

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  const int rc = RUN_ALL_TESTS();
  const auto& unit = *::testing::UnitTest::GetInstance();
  if (rc == 0 && unit.test_to_run_count() > 0 && unit.skipped_test_count() == unit.test_to_run_count()) return 77;
  return rc;
}
