# SPDX-License-Identifier: GPL-3.0-or-later
# `cmake --install build --prefix P`: headers, libphysreg, the physreg program, the Python package
# and a CMake package so that downstream projects can `find_package(physreg CONFIG REQUIRED)`.
include(CMakePackageConfigHelpers)
install(TARGETS physreg EXPORT physregTargets
        LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
        RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(TARGETS physreg_cli RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(DIRECTORY ${PROJECT_SOURCE_DIR}/include/physreg DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}
        FILES_MATCHING PATTERN "*.hpp")
install(FILES ${PROJECT_BINARY_DIR}/generated/physreg/core/version.hpp DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/physreg/core)
install(FILES ${PROJECT_SOURCE_DIR}/LICENSE DESTINATION ${CMAKE_INSTALL_DATADIR}/doc/physreg)
set(PHYSREG_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/physreg)
install(EXPORT physregTargets NAMESPACE physreg:: DESTINATION ${PHYSREG_CMAKE_DIR})
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/physregConfig.cmake.in
                              ${PROJECT_BINARY_DIR}/physregConfig.cmake
                              INSTALL_DESTINATION ${PHYSREG_CMAKE_DIR}
                              PATH_VARS CMAKE_INSTALL_BINDIR)
write_basic_package_version_file(${PROJECT_BINARY_DIR}/physregConfigVersion.cmake COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/physregConfig.cmake ${PROJECT_BINARY_DIR}/physregConfigVersion.cmake
        DESTINATION ${PHYSREG_CMAKE_DIR})
