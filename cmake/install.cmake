# `cmake --install build --prefix P`: headers, libraries, the CLI and a CMake package, so that an outside project's
# find_package(voxwarp CONFIG REQUIRED) and target_link_libraries(app voxwarp::voxwarp) work.
include(CMakePackageConfigHelpers)

install(TARGETS voxwarp_core voxwarp_voxelize voxwarp_warp voxwarp_extract voxwarp_metrics voxwarp_deform voxwarp_all
  EXPORT voxwarpTargets
  LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR}
  INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
foreach(dir libcore libvoxelize libwarp libextract libmetrics libdeform)
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/${dir}/include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
endforeach()
install(TARGETS voxwarp_cli RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})

install(EXPORT voxwarpTargets NAMESPACE voxwarp:: DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/voxwarp)
configure_package_config_file(${CMAKE_CURRENT_LIST_DIR}/voxwarpConfig.cmake.in ${CMAKE_BINARY_DIR}/voxwarpConfig.cmake
  INSTALL_DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/voxwarp)
write_basic_package_version_file(${CMAKE_BINARY_DIR}/voxwarpConfigVersion.cmake COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_BINARY_DIR}/voxwarpConfig.cmake ${CMAKE_BINARY_DIR}/voxwarpConfigVersion.cmake DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/voxwarp)
