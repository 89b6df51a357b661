# Sourced by scripts/setup.sh and scripts/fuzz.sh: the C++ compiler of a new build folder.
# GEO_CXX=clang (the default) takes clang++ where it is installed, else g++; GEO_CXX=gcc takes g++.
# Clang's precompiled header holds LibTorch's template instantiations, which GCC makes again in
# every translation unit: a fresh build in about a third of GCC's CPU time.
geo_cxx() {
  if [ "${GEO_CXX:-clang}" = clang ] && command -v clang++ >/dev/null; then echo clang++; else echo g++; fi
}
