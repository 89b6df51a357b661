# Sourced by scripts/setup.sh and scripts/fuzz.sh: the C++ compiler of a new build folder.
# Clang's precompiled header holds LibTorch's template instantiations, which GCC makes again in
# every translation unit: a fresh build takes about a third of GCC's CPU time.
#   geo_cxx_choice  GEO_CXX (clang or gcc; default clang)
#   geo_cxx         the compiler to configure with: clang++ when chosen and installed, else g++
geo_cxx_choice() { echo "${GEO_CXX:-clang}"; }
geo_cxx() {
  if [ "$(geo_cxx_choice)" = clang ] && command -v clang++ >/dev/null; then echo clang++; else echo g++; fi
}
