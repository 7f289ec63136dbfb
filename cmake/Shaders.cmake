# hysar_add_shaders(TARGET <name> SOURCES <files...> [FP32_VARIANTS <files...>])
# Compiles each GLSL file to SPIR-V with glslangValidator and wraps the words in a generated
# header "shaders/<stem>_<stage>.h" holding `static const uint32_t k<Stem><Stage>Spv[]`.
# Each of FP32_VARIANTS is compiled a second time with HS_NO_FLOAT64 defined, for devices
# without shaderFloat64, into "shaders/<stem>_<stage>_f32.h" (`k<Stem><Stage>SpvF32`).
# A shader error is a build error. Nothing generated lands in the source tree.
function(hysar_add_shaders)
    cmake_parse_arguments(ARG "" "TARGET" "SOURCES;DEPENDS;FP32_VARIANTS" ${ARGN})
    set(gen_dir ${CMAKE_BINARY_DIR}/generated/shaders)
    file(MAKE_DIRECTORY ${gen_dir})
    set(headers)
    foreach(src ${ARG_SOURCES})
        get_filename_component(name ${src} NAME)          # shade.frag
        get_filename_component(stem ${src} NAME_WE)       # shade
        get_filename_component(ext ${src} LAST_EXT)       # .frag
        string(SUBSTRING ${ext} 1 -1 stage)
        # kShadeFragSpv
        string(SUBSTRING ${stem} 0 1 first)
        string(TOUPPER ${first} first)
        string(SUBSTRING ${stem} 1 -1 rest)
        string(SUBSTRING ${stage} 0 1 sfirst)
        string(TOUPPER ${sfirst} sfirst)
        string(SUBSTRING ${stage} 1 -1 srest)
        set(var "k${first}${rest}${sfirst}${srest}Spv")
        set(out ${gen_dir}/${stem}_${stage}.h)
        add_custom_command(
            OUTPUT ${out}
            COMMAND ${GLSLANG_VALIDATOR} -V --target-env vulkan1.3 -g0
                    -I${CMAKE_CURRENT_SOURCE_DIR} --vn ${var} -o ${out}
                    ${CMAKE_CURRENT_SOURCE_DIR}/${src}
            DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/${src} ${ARG_DEPENDS}
            COMMENT "glslang ${name}"
            VERBATIM)
        list(APPEND headers ${out})
        if(src IN_LIST ARG_FP32_VARIANTS)
            set(out32 ${gen_dir}/${stem}_${stage}_f32.h)
            add_custom_command(
                OUTPUT ${out32}
                COMMAND ${GLSLANG_VALIDATOR} -V --target-env vulkan1.3 -g0 -DHS_NO_FLOAT64=1
                        -I${CMAKE_CURRENT_SOURCE_DIR} --vn ${var}F32 -o ${out32}
                        ${CMAKE_CURRENT_SOURCE_DIR}/${src}
                DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/${src} ${ARG_DEPENDS}
                COMMENT "glslang ${name} (fp32)"
                VERBATIM)
            list(APPEND headers ${out32})
        endif()
    endforeach()
    add_custom_target(${ARG_TARGET}_spv DEPENDS ${headers})
    add_library(${ARG_TARGET} INTERFACE)
    add_dependencies(${ARG_TARGET} ${ARG_TARGET}_spv)
    target_include_directories(${ARG_TARGET} INTERFACE ${CMAKE_BINARY_DIR}/generated
                                                       ${CMAKE_CURRENT_SOURCE_DIR}/..)
endfunction()
