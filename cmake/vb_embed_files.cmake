# vb_embed_files(OUT HEADER NAMESPACE COMMENT FILES "name=path" ...): a build step that embeds files into a .cc
# (cmake/embed.cmake writes it; HEADER declares the lookup), rebuilt when a file changes. The web dashboard's
# assets and the HTML report's inlined scripts both use it.
function(vb_embed_files)
  cmake_parse_arguments(E "" "OUT;HEADER;NAMESPACE;COMMENT" "FILES" ${ARGN})
  set(paths "")
  foreach(pair IN LISTS E_FILES)
    string(REGEX REPLACE "^[^=]*=" "" path "${pair}")
    list(APPEND paths "${path}")
  endforeach()
  string(REPLACE ";" "\\;" files_arg "${E_FILES}")
  add_custom_command(
    OUTPUT ${E_OUT}
    COMMAND ${CMAKE_COMMAND} -DOUT=${E_OUT} "-DFILES=${files_arg}" -DHEADER=${E_HEADER} -DNAMESPACE=${E_NAMESPACE}
            -P ${CMAKE_SOURCE_DIR}/cmake/embed.cmake
    DEPENDS ${paths} ${CMAKE_SOURCE_DIR}/cmake/embed.cmake
    COMMENT "${E_COMMENT}")
endfunction()
