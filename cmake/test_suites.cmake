# Script mode (run after a test executable is built): one ctest test per GoogleTest suite of the
# executable, named "Suite.*" and running --gtest_filter=Suite.*: a process per suite instead of one
# per test (each LibTorch process takes ~0.6-1 s to start). A suite whose every test skipped exits
# 77 (tests/support/gtest_main.cpp), ctest's skip code here; a failure is never hidden by a skip.
#   cmake -D EXE=<executable> -D OUT=<ctest file> -D WORKDIR=<dir> -P test_suites.cmake
execute_process(COMMAND "${EXE}" --gtest_list_tests OUTPUT_VARIABLE listing ERROR_VARIABLE errors
                RESULT_VARIABLE rc TIMEOUT 120)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "${EXE} --gtest_list_tests failed (${rc}): ${errors}")
endif()
get_filename_component(exe_name "${EXE}" NAME)
string(REPLACE ";" "\\;" listing "${listing}")
string(REPLACE "\n" ";" lines "${listing}")
set(text "# ${exe_name}'s suites (cmake/test_suites.cmake)\n")
set(count 0)
foreach(line IN LISTS lines)
  # A suite's line is its name and a dot at the start of a line (tests are indented under it).
  if(line MATCHES "^([A-Za-z_][A-Za-z0-9_/]*)\\.")
    set(suite "${CMAKE_MATCH_1}")
    string(MAKE_C_IDENTIFIER "${suite}" id)
    # Two executables with a suite of the same name would make two ctest tests of one name.
    string(APPEND text
           "if(DEFINED geo_suite_${id})\n"
           "  message(FATAL_ERROR \"the test suite ${suite} is in both \${geo_suite_${id}} and ${exe_name}: rename one\")\n"
           "endif()\n"
           "set(geo_suite_${id} ${exe_name})\n"
           "add_test([=[${suite}.*]=] [==[${EXE}]==] [==[--gtest_filter=${suite}.*]==])\n"
           "set_tests_properties([=[${suite}.*]=] PROPERTIES WORKING_DIRECTORY [==[${WORKDIR}]==] SKIP_RETURN_CODE 77)\n")
    math(EXPR count "${count} + 1")
  endif()
endforeach()
if(count EQUAL 0)
  message(FATAL_ERROR "${EXE} lists no test suite")
endif()
file(WRITE "${OUT}" "${text}")
