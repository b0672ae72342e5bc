# SPDX-License-Identifier: GPL-3.0-or-later
add_executable(scratch_asan unit/scratch_asan.cpp)
target_include_directories(scratch_asan PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/unit ${CMAKE_CURRENT_SOURCE_DIR}/unit/mechanics)
target_link_libraries(scratch_asan PRIVATE physreg::physreg GTest::gtest_main ZLIB::ZLIB)
target_compile_definitions(scratch_asan PRIVATE PHYSREG_SHARED_DATA_DIR="${PROJECT_SOURCE_DIR}/../shared/data")
