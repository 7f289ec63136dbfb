# `hysar render --check` on a render that cannot agree with its reference: the room's lights made
# 20x brighter, rendered into an 8-bit unorm target (which holds at most 1.0). The command must
# say which images disagree, write that into render.json and exit with status 3.
file(READ ${SOURCE}/configs/exp1-room.json scene)
string(REPLACE "\"intensity\": 0.9," "\"intensity\": 18," scene "${scene}")
string(REPLACE "\"intensity\": 0.28," "\"intensity\": 5.6," scene "${scene}")
file(WRITE ${DIR}/bright-room.json "${scene}")
execute_process(
    COMMAND ${CMAKE_COMMAND} -E env HYSAR_VALIDATION=1 ${HYSAR} render --scene ${DIR}/bright-room.json
            --out ${DIR}/out --format rgba8 --angles 0 --model phong --no-exr --check
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 3)
    message(FATAL_ERROR "expected exit status 3 (disagrees with the reference), got ${rc}\n${out}\n${err}")
endif()
if(NOT out MATCHES "images disagree with the reference beyond the stated tolerance")
    message(FATAL_ERROR "no summary of the disagreement on stdout:\n${out}")
endif()
if(NOT err MATCHES "disagree with the reference \\(--check\\)")
    message(FATAL_ERROR "no --check message on stderr:\n${err}")
endif()
file(READ ${DIR}/out/render.json j)
string(JSON n LENGTH "${j}" disagreements)
if(n LESS 1)
    message(FATAL_ERROR "render.json lists no disagreement")
endif()
string(JSON ok GET "${j}" images 1 error within_tolerance)
if(ok)
    message(FATAL_ERROR "render.json calls the clipped phong image within tolerance")
endif()
