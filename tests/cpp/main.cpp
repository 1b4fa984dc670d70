// The doctest runner of the C++ unit tests (tests/cpp/<csrc folder>/test_<unit>.cpp, one binary).
#define DOCTEST_CONFIG_IMPLEMENT_WITH_MAIN
#include <doctest/doctest.h>
