# Runs at install time (cmake --install, and CPack staging the Debian package): the files whose contents depend
# on where the tree is installed. VB_PACKAGING_DIR is set by the install rule before this file is included.
#   prefix /usr (the Debian package): /etc/valvebench/server.json, store in /var/lib/valvebench (FHS)
#   any other prefix DIR: DIR/etc/valvebench/server.json, store in DIR/var/lib/valvebench, so DIR runs alone
# An existing server.json is never overwritten (it is the operator's): the new one goes beside it as
# server.json.new. (The package's conffile handling is dpkg's: CPack stages into an empty directory.)
set(_prefix "${CMAKE_INSTALL_PREFIX}")
if(_prefix STREQUAL "/usr")
  set(VB_ETC_DIR /etc/valvebench)
  set(VB_STATE_DIR /var/lib/valvebench)
else()
  set(VB_ETC_DIR "${_prefix}/etc/valvebench")
  set(VB_STATE_DIR "${_prefix}/var/lib/valvebench")
endif()
set(VB_BIN_DIR "${_prefix}/bin")
set(_dest "$ENV{DESTDIR}")

set(_config "${_dest}${VB_ETC_DIR}/server.json")
if(EXISTS "${_config}")
  set(_config "${_config}.new")
  message(STATUS "Keeping the existing ${_dest}${VB_ETC_DIR}/server.json; the installed default is ${_config}")
endif()
configure_file("${VB_PACKAGING_DIR}/server.json.in" "${_config}" @ONLY)
file(CHMOD "${_config}" PERMISSIONS OWNER_READ OWNER_WRITE GROUP_READ)
configure_file("${VB_PACKAGING_DIR}/valvebench.service.in"
               "${_dest}${_prefix}/lib/systemd/system/valvebench.service" @ONLY)
list(APPEND CMAKE_INSTALL_MANIFEST_FILES "${_config}" "${_dest}${_prefix}/lib/systemd/system/valvebench.service")
message(STATUS "Installing: ${_config}")
message(STATUS "Installing: ${_dest}${_prefix}/lib/systemd/system/valvebench.service")
if(NOT _prefix STREQUAL "/usr" OR _dest STREQUAL "")
  # The package's postinst creates /var/lib/valvebench for its service user (staged with DESTDIR, it is not
  # made here, so dpkg does not own it); a tree in DIR, or a plain install into /usr, gets it here.
  file(MAKE_DIRECTORY "${_dest}${VB_STATE_DIR}")
endif()
