# hysar_embed_text(VAR FILE TEMPLATE OUTPUT): generates OUTPUT from TEMPLATE with the contents of
# FILE in @VAR@, and re-runs the configuration when FILE changes.
function(hysar_embed_text var file template output)
    file(READ ${file} ${var})
    set_property(DIRECTORY APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS ${file})
    configure_file(${template} ${output} @ONLY)
endfunction()
