# Sourced by scripts/setup.sh and scripts/fuzz.sh: the C++ compiler of a new build folder.
# Clang's precompiled header holds LibTorch's template instantiations, which GCC makes again in
# every translation unit: a fresh build takes about a third of GCC's CPU time.
# geo_cxx: clang++ when GEO_CXX is clang (the default) and Clang is installed, else g++.
geo_cxx() {
  if [ "${GEO_CXX:-clang}" = clang ] && command -v clang++ >/dev/null; then echo clang++; else echo g++; fi
}
