# CPACK_PROJECT_CONFIG_FILE: read by cpack at packaging time. VB_PACKAGE_VERSION in the environment overrides
# the version (the package test builds an older-versioned package of the same tree to upgrade from).
if(DEFINED ENV{VB_PACKAGE_VERSION} AND NOT "$ENV{VB_PACKAGE_VERSION}" STREQUAL "")
  set(CPACK_PACKAGE_VERSION "$ENV{VB_PACKAGE_VERSION}")
  set(CPACK_DEBIAN_PACKAGE_VERSION "$ENV{VB_PACKAGE_VERSION}")
endif()
