# geo's layers, checked when CMake configures, and written to <build>/layers.txt:
#
#   core -> geometry -> photometric -> losses -> train_parts -> training
#           geometry -> models, photometric -> pipeline -> { geo (the library), train_parts }
#                                  data -> data_io -> evaluation (on geo and pipeline, never training)
#                                          data_io -> training_data (what a config trains on) -> training
#   core -> metrics (tensors only) -> evaluation
#
# geo_layers_check(TARGET NOT forbidden...) fails the configuration when TARGET links, directly or
# through any of its dependencies, one of the forbidden targets.

# Every target TARGET links, directly or transitively (its link and interface link libraries).
function(geo_link_closure target out)
  set(seen "")
  set(todo ${target})
  while(todo)
    list(POP_FRONT todo t)
    if(NOT TARGET ${t} OR t IN_LIST seen)
      continue()
    endif()
    list(APPEND seen ${t})
    get_target_property(type ${t} TYPE)
    set(libs "")
    if(NOT type STREQUAL "INTERFACE_LIBRARY")
      get_target_property(libs ${t} LINK_LIBRARIES)
    endif()
    get_target_property(ilibs ${t} INTERFACE_LINK_LIBRARIES)
    foreach(l IN LISTS libs ilibs)
      if(l AND TARGET ${l})
        list(APPEND todo ${l})
      endif()
    endforeach()
  endwhile()
  list(REMOVE_ITEM seen ${target})
  set(${out} ${seen} PARENT_SCOPE)
endfunction()

set(GEO_LAYERS_REPORT "")
function(geo_layers_check target)
  cmake_parse_arguments(ARG "" "" "NOT;ABOVE" ${ARGN})
  if(NOT TARGET ${target})
    return()
  endif()
  geo_link_closure(${target} closure)
  foreach(f IN LISTS ARG_NOT)
    if(f IN_LIST closure)
      message(FATAL_ERROR "geo layers: ${target} links ${f} (it must not: see cmake/layers.cmake)")
    endif()
  endforeach()
  foreach(a IN LISTS ARG_ABOVE)
    if(NOT a IN_LIST closure)
      message(FATAL_ERROR "geo layers: ${target} does not sit on ${a} (see cmake/layers.cmake)")
    endif()
  endforeach()
  set(own "")
  foreach(t IN LISTS closure)
    if(t MATCHES "^geo(_|$)")
      list(APPEND own ${t})
    endif()
  endforeach()
  list(JOIN own " " own)
  set(GEO_LAYERS_REPORT "${GEO_LAYERS_REPORT}${target}: ${own}\n" PARENT_SCOPE)
endfunction()

set(geo_training_layers geo_train_parts geo_training)
# Inference (the pipeline, the library) links the photometric error for the FlowNet's input, never
# the losses.
geo_layers_check(geo_pipeline NOT ${geo_training_layers} geo_losses geo_evaluation geo_data geo_data_io geo)
geo_layers_check(geo NOT ${geo_training_layers} geo_losses geo_evaluation geo_data geo_data_io ABOVE geo_pipeline)
# The metrics on tensors: LibTorch and core only (the OpenCV-free build and Python use them).
geo_layers_check(geo_metrics NOT geo_geometry geo_models geo_pipeline geo_data ${geo_training_layers} geo)
geo_layers_check(geo_evaluation NOT ${geo_training_layers} ABOVE geo geo_pipeline)
geo_layers_check(geo_train_parts NOT geo_evaluation geo ABOVE geo_pipeline)
geo_layers_check(geo_training NOT geo_evaluation geo ABOVE geo_pipeline)
# The data a config trains on: readers only (geo_prepare links it and no training).
geo_layers_check(geo_training_data NOT ${geo_training_layers} geo_pipeline geo_evaluation geo)
geo_layers_check(geo_prepare NOT ${geo_training_layers} geo_pipeline)
file(WRITE ${PROJECT_BINARY_DIR}/layers.txt
     "# Each geo library and every geo library it links (directly or not); checked by cmake/layers.cmake\n"
     "${GEO_LAYERS_REPORT}")
