# The include side of geo's layers (cmake/layers.cmake checks the link side); run by ctest as
#   cmake -DSOURCE_DIR=<repo> -P cmake/check_includes.cmake
# Fails naming the file and the include that crosses a layer.
cmake_policy(SET CMP0057 NEW)  # if(... IN_LIST ...)
set(errors "")

# forbid(<glob> <regex of forbidden include targets> <why>)
function(forbid glob regex why)
  file(GLOB files ${SOURCE_DIR}/${glob})
  if(NOT files)
    message(FATAL_ERROR "check_includes: no files match ${glob}")
  endif()
  foreach(f IN LISTS files)
    file(STRINGS ${f} lines REGEX "^[ \t]*#[ \t]*include")
    foreach(line IN LISTS lines)
      if(line MATCHES "${regex}")
        file(RELATIVE_PATH rel ${SOURCE_DIR} ${f})
        set(errors "${errors}${rel}: '${line}' (${why})\n" PARENT_SCOPE)
      endif()
    endforeach()
  endforeach()
endfunction()

# forbid_code(<glob> <regex> <why> [files allowed]): like forbid, over every line of code.
function(forbid_code glob regex why)
  file(GLOB files ${SOURCE_DIR}/${glob})
  foreach(f IN LISTS files)
    file(RELATIVE_PATH rel ${SOURCE_DIR} ${f})
    set(allowed ${ARGN})
    if(rel IN_LIST allowed)
      continue()
    endif()
    file(STRINGS ${f} lines REGEX "${regex}")
    foreach(line IN LISTS lines)
      if(NOT line MATCHES "^[ \t]*//")
        set(errors "${errors}${rel}: '${line}' (${why})\n" PARENT_SCOPE)
      endif()
    endforeach()
  endforeach()
endfunction()

forbid("src/pipeline/*" "[\"<](train|eval|data|api)/" "the pipeline layer sits below training, evaluation and data")
forbid("src/pipeline/*" "[\"<]losses/(total_loss|smoothness|consistency)\\.h" "inference links the photometric error (geo_photometric), not the losses")
forbid("src/api/*" "[\"<](train|eval|data)/" "the library is built on the pipeline layer only")
forbid("src/eval/*" "[\"<]train/" "evaluation does not depend on training")
foreach(glob "src/data/*" "src/data/*/*")  # data/ and its rooms by source (kitti, synth, packed, video)
  forbid("${glob}" "[\"<](train|eval|api|pipeline)/" "data readers sit below the networks, training and evaluation")
endforeach()
# Every convolution of the networks goes through geo's (models/conv.h: the oneDNN channel fix).
foreach(dir models pipeline)
  forbid_code("src/${dir}/*" "torch::nn::Conv2d[^IO]|torch::nn::Conv2d$|torch::conv2d\\(|at::conv2d\\("
              "a convolution outside geo::Conv2d / geo::conv2d skips the oneDNN channel fix (models/conv.h)"
              src/models/conv.cpp src/models/conv.h)
endforeach()
# The public header: LibTorch and the standard library only (no OpenCV, yaml-cpp, spdlog, fmt, geo internals).
forbid("include/geo/*.h" "\"|<(opencv|yaml|spdlog|fmt|CLI)" "the public header includes LibTorch and the standard library only")

if(errors)
  message(FATAL_ERROR "includes or code that break geo's layers:\n${errors}")
endif()
message(STATUS "geo's layers: every include is within its layer")
